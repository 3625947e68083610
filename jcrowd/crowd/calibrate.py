"""Calibrating the pedestrian dynamics to measured trajectories, by gradient (issue 22, item 2).

The collision-free speed model's parameters (:class:`~jcrowd.crowd.avoidance.AvoidanceParams`)
and the free walking speed ``v0`` are fitted to measured runs by Levenberg–Marquardt
(optimistix) through differentiable rollouts (:mod:`jcrowd.crowd.rollout`).

Readings taken, and why:

- **Short horizons from measured states.** A whole HERMES run cannot be differentiated: its
  dense runs jam before the exit, where the pathwise derivative grows about ×1.4 per step
  (:mod:`jcrowd.crowd.rollout`, "Limits"). The fit therefore compares the model with the
  measurement over short *windows*: every ``every_s`` seconds of a run's steady state, every
  person present is placed where they were measured, with their measured velocity (a
  ``VELOCITY_S`` difference), and the crowd is simulated ``horizon_s`` seconds (0.5 s: 15 steps
  of 1/30 s, 8 frames of 16 fps). This is the usual trajectory-based calibration of
  microscopic models (a prediction from the measured state, not a free run), and it keeps the
  derivative meaningful: at 1.5 s (45 steps) the Jacobian reached 10³–10⁴ in the densest runs
  (``uo-050-070-070``; 10² in ``uo-050-180-180``), at 0.5 s it stays bounded.
- **What it does not achieve (measured).** The fitted ``time_gap`` does not lower the free
  run's fundamental-diagram speed error below the hand-chosen defaults' (``bench/calibrate.py``,
  0.138 m/s): ``time_gap`` alone from three starts gives 0.276–0.281 s (1.7 % apart) and
  0.136–0.141 m/s; with ``desired_speed`` too, 0.305 s and 1.459 m/s and 0.158–0.183 m/s (the
  free run is chaotic: fits 2 % apart move it by ±0.005 m/s). The windows and the fundamental
  diagram want different things of ``T``. From the measured states, the model at the default
  ``T`` = 0.6 s walks slower than the people in every run (mean window residual −0.15 to
  −0.37 m/s; at 0.3 s, −0.14 to +0.09): that is where the fit goes. In a free run a short ``T``
  lets the corridor carry the measured inflow at a lower density and a higher speed than
  measured — ``uo-180-180-180``, which has no bottleneck, was congested (1.68 /m² at
  0.96 m/s) and the model carries the same ~1.6 /m/s at 1.35 /m² and 1.21 m/s with
  ``T`` = 0.305 s — so the per-run speed error there grows as ``T`` falls, while in the
  bottleneck runs it shrinks. On a grid (``v0`` = 1.34 m/s), the fundamental diagram is best
  near ``T`` = 0.5 s (0.117 m/s), where the windows' mean residual is −0.12 to −0.29 m/s. A
  1.0 s horizon does not help: its Jacobian reached 3.3·10³ and Levenberg–Marquardt stayed at
  its start. Fitting ``desired_speed`` moves it to 1.46 m/s, faster than the free-flow runs'
  measured 1.34–1.39 m/s; adding ``plain_reaction_time`` is degenerate (``T`` → 0.005 s,
  ``τ`` → 1.4 s absorb the start's mismatch).
- **What is compared.** Per window, the mean speed over the horizon (displacement ÷
  ``horizon_s``) of the people who start in the run's measurement area, simulated minus
  measured: one residual per window, in m/s. The fundamental diagram the result is judged by
  (``bench/pedestrians.py``'s ``fd_speed_rmse_m_s``) is PedPy's speed in that area, so the fit
  targets the same people and the same quantity on a shorter time scale. Windows where nobody
  starts in the area count zero.
- **What is fitted.** By default ``time_gap`` (``T``, how far ahead people keep their
  spacing) alone: the windows fix it well (one optimum from every start), while ``v0`` comes
  out biased and the reaction time degenerate (above). Any field of
  :class:`~jcrowd.crowd.avoidance.AvoidanceParams` and ``desired_speed`` (``v0``) may be
  named. The repulsion's ``strength``/``range``, ``wall_strength`` and ``anisotropy`` move the
  residuals by less than 1 % of ``T``'s effect (their columns of the Jacobian at the
  defaults); a fit of them is set by noise. Parameters are fitted as logarithms (each stays
  positive; a step is relative).
- **Structure held by the forward pass.** As in every rollout, who is the nearest neighbour
  ahead is decided by the forward pass and carries no gradient (:mod:`jcrowd.crowd.rollout`).

Geometry (:func:`corridor_scene`): the HERMES corridor of the shared data's README — walkable
``x ∈ [0, b]``, ``y ∈ [-4, 4]`` with the rooms before and after it, an exit of the run's width
centred in a 0.2 m wall at ``y = -4`` and the target 2.5 m behind it; the measurement area
``x ∈ [0, b]``, ``y ∈ [-2, 0]``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import shapely
from jaxtyping import Array, Bool, Float
from shapely.ops import nearest_points

from jcrowd.crowd.avoidance import AvoidanceParams
from jcrowd.crowd.dynamics import Pedestrians, World, build_world
from jcrowd.crowd.rollout import RolloutParams, RolloutSetup, rollout
from jcrowd.errors import JcrowdError

__all__ = [
    "DEFAULT_NAMES",
    "Calibration",
    "WindowBatch",
    "calibrate",
    "corridor_scene",
    "make_windows",
    "merge_windows",
    "parameter_values",
    "window_residuals",
]

DEFAULT_NAMES = ("time_gap",)
"""The parameters fitted by default (module docstring)."""

SPEED_NAME = "desired_speed"
"""The free walking speed ``v0`` (m/s), fitted beside the avoidance model's fields."""

DT = 1.0 / 30.0
VELOCITY_S = 0.25
"""The measured start velocity is the displacement over the last ``VELOCITY_S`` seconds."""

RADIUS = 0.2
"""Body radius (m) of the simulated people, as in the crowd-dynamics bench."""


def corridor_scene(
    corridor_m: float, exit_m: float
) -> tuple[shapely.Polygon, shapely.Polygon, tuple[float, float, float, float]]:
    """The HERMES corridor's walkable area, its target and measurement area
    ``(x0, x1, y0, y1)`` for a corridor ``corridor_m`` wide with an exit ``exit_m`` wide."""
    c, b = float(corridor_m), float(exit_m)
    if not (0.5 <= c <= 10.0 and 0.2 <= b <= c):
        raise JcrowdError(
            f"calibrate: expected a corridor 0.5-10 m wide and an exit 0.2 m to the corridor's "
            f"width, found {c} m and {b} m"
        )
    area = shapely.Polygon(
        [
            (c + 1, -6.5),
            (c + 1, -4),
            (c, -4),
            (c, 4),
            (c + 1, 4),
            (c + 1, 8),
            (-1, 8),
            (-1, 4),
            (0, 4),
            (0, -4),
            (-1, -4),
            (-1, -6.5),
        ]
    )
    if b < c - 1e-6:
        wall = shapely.union(
            shapely.box(-1.0, -4.2, c / 2 - b / 2, -4.0),
            shapely.box(c / 2 + b / 2, -4.2, c + 1, -4.0),
        )
        area = area.difference(wall)
    return area, shapely.box(-1.0, -6.5, c + 1, -6.0), (0.0, c, -2.0, 0.0)


class WindowBatch(eqx.Module):
    """Every window of one scene, padded to one agent count.

    Attributes:
        world: the scene.
        position, velocity: ``(W, N, 2)`` measured at each window's start (m, m/s).
        alive: ``(W, N)`` a measured person (else padding).
        end: ``(W, N, 2)`` measured at the window's end.
        counted: ``(W, N)`` starts in the measurement area and is measured at the end.
        steps: simulation steps per window.
    """

    world: World
    position: Float[Array, "W N 2"]
    velocity: Float[Array, "W N 2"]
    alive: Bool[Array, "W N"]
    end: Float[Array, "W N 2"]
    counted: Bool[Array, "W N"]
    steps: int = eqx.field(static=True)


def _positions_at(rows: np.ndarray, frame: int) -> dict[int, np.ndarray]:
    sel = rows[rows[:, 1] == frame]
    return {int(r[0]): r[2:4] for r in sel}


def make_windows(
    rows: np.ndarray,
    fps: float,
    frames: tuple[int, int],
    corridor_m: float,
    exit_m: float,
    *,
    horizon_s: float = 0.5,
    every_s: float = 2.0,
    agents: int = 0,
) -> tuple[WindowBatch, np.ndarray]:
    """The windows of one run (module docstring) and each window's start frame.

    Args:
        rows: ``(R, 4)`` ``id, frame, x, y`` in metres (people walk towards −y).
        fps: the recording's frame rate.
        frames: the frames windows may span (the steady state).
        corridor_m, exit_m: the scene (:func:`corridor_scene`).
        horizon_s: simulated seconds per window; a whole number of frames and of 1/30 s steps.
        every_s: seconds between window starts.
        agents: pad to this many agents (0: one more than the most present at any start,
            rounded up to 8); the last column is always padding, parked in the target.

    Raises:
        JcrowdError: a horizon that is not a whole number of frames and steps, or a span with
            no window.
    """
    hf, steps = horizon_s * fps, horizon_s / DT
    if not (abs(hf - round(hf)) < 1e-6 and abs(steps - round(steps)) < 1e-6 and hf >= 1):
        raise JcrowdError(
            f"calibrate: expected a horizon of whole frames at {fps} fps and whole 1/30 s steps, "
            f"found {horizon_s} s"
        )
    h, vf = round(hf), max(1, round(VELOCITY_S * fps))
    starts = np.arange(frames[0] + vf, frames[1] - h + 1, max(1, round(every_s * fps)))
    if len(starts) == 0:
        raise JcrowdError(
            f"calibrate: expected frames {frames} to hold a {horizon_s} s window after "
            f"{VELOCITY_S} s of history, found too few"
        )
    area, target, (x0, x1, y0, y1) = corridor_scene(corridor_m, exit_m)
    world = build_world(area, [target])
    inner = area.buffer(-RADIUS - 0.02)
    per: list[tuple[np.ndarray, ...]] = []
    for s in starts:
        now, before, later = (_positions_at(rows, int(f)) for f in (s, s - vf, s + h))
        ids = sorted(now)
        p0 = np.array([now[i] for i in ids]).reshape(-1, 2)
        v0 = np.array([(now[i] - before[i]) * fps / vf if i in before else (0, 0) for i in ids])
        # A measured head can stand within a body radius of a wall; start it just inside.
        for k, p in enumerate(p0):
            point = shapely.Point(p)
            if not inner.contains(point):
                near = nearest_points(inner, point)[0]
                p0[k] = (near.x, near.y)
        end = np.array([later.get(i, now[i]) for i in ids]).reshape(-1, 2)
        start_xy = np.array([now[i] for i in ids]).reshape(-1, 2)
        inside = (start_xy[:, 0] >= x0) & (start_xy[:, 0] <= x1)
        inside &= (start_xy[:, 1] >= y0) & (start_xy[:, 1] <= y1)
        counted = inside & np.array([i in later for i in ids], bool)
        per.append((p0, v0.reshape(-1, 2), end, counted, start_xy))
    most = max(len(p[0]) for p in per)
    n = agents or int(8 * np.ceil((most + 1) / 8))
    if most >= n:
        raise JcrowdError(
            f"calibrate: expected fewer than {n} people per window (one column stays padding), "
            f"found {most}"
        )
    park = np.array(target.centroid.coords[0])
    w = len(per)
    pos, vel, end = np.tile(park, (w, n, 1)), np.zeros((w, n, 2)), np.tile(park, (w, n, 1))
    alive, counted = np.zeros((w, n), bool), np.zeros((w, n), bool)
    for k, (p0, v0, e, c, sxy) in enumerate(per):
        m = len(p0)
        pos[k, :m], vel[k, :m], alive[k, :m], counted[k, :m] = p0, v0, True, c
        # The residual compares displacements from where the person was measured.
        end[k, :m] = e - sxy + p0
    f32 = jnp.float32
    batch = WindowBatch(
        world,
        jnp.asarray(pos, f32),
        jnp.asarray(vel, f32),
        jnp.asarray(alive),
        jnp.asarray(end, f32),
        jnp.asarray(counted),
        round(steps),
    )
    return batch, starts


def merge_windows(batches: Sequence[WindowBatch]) -> list[WindowBatch]:
    """Batches of the same scene (equal walls) joined into one, padded to one agent count: one
    compiled rollout per scene instead of one per run."""
    groups: list[list[WindowBatch]] = []
    for b in batches:
        for g in groups:
            w = g[0].world.walls
            if w.shape == b.world.walls.shape and bool(jnp.all(w == b.world.walls)):
                if g[0].steps == b.steps and g[0].world.grid == b.world.grid:
                    g.append(b)
                    break
        else:
            groups.append([b])
    out = []
    for g in groups:
        n = max(b.position.shape[1] for b in g)

        def pad(a: Array, n: int = n, fill: Array | None = None) -> Array:
            extra = n - a.shape[1]
            if fill is None:
                width = [(0, 0), (0, extra)] + [(0, 0)] * (a.ndim - 2)
                return jnp.pad(a, width)
            tail = jnp.broadcast_to(fill, (a.shape[0], extra, *a.shape[2:]))
            return jnp.concatenate([a, tail.astype(a.dtype)], axis=1)

        park = g[0].position[0, -1]  # make_windows keeps the last column a pad
        out.append(
            WindowBatch(
                g[0].world,
                jnp.concatenate([pad(b.position, fill=park) for b in g]),
                jnp.concatenate([pad(b.velocity) for b in g]),
                jnp.concatenate([pad(b.alive) for b in g]),
                jnp.concatenate([pad(b.end, fill=park) for b in g]),
                jnp.concatenate([pad(b.counted) for b in g]),
                g[0].steps,
            )
        )
    return out


def parameter_values(
    names: Sequence[str], values: Float[Array, " P"], base: AvoidanceParams
) -> tuple[AvoidanceParams, Float[Array, ""]]:
    """``base`` with the named fields set to ``values``, and the desired speed (``names`` may
    hold ``desired_speed``; without it, the crowd-dynamics bench's 1.34 m/s)."""
    speed = jnp.asarray(1.34, values.dtype)
    params = base
    for k, name in enumerate(names):
        if name == SPEED_NAME:
            speed = values[k]
        else:
            params = eqx.tree_at(_field(name), params, values[k])
    return params, speed


def _field(name: str) -> Callable[[AvoidanceParams], Array]:
    def get(p: AvoidanceParams) -> Array:
        return cast(Array, getattr(p, name))

    return get


def _check_names(names: Sequence[str]) -> None:
    fields = set(AvoidanceParams.__dataclass_fields__) | {SPEED_NAME}
    bad = [n for n in names if n not in fields]
    if bad or not names or len(set(names)) != len(names):
        raise JcrowdError(
            f"calibrate: expected distinct parameter names among {sorted(fields)}, found "
            f"{list(names)}"
        )


def _end_positions(
    params: AvoidanceParams, speed: Float[Array, ""], batch: WindowBatch
) -> tuple[Float[Array, "W N 2"], Array]:
    n = batch.position.shape[1]

    def one(position: Array, velocity: Array, alive: Array) -> tuple[Array, Array]:
        peds = Pedestrians(
            position,
            jnp.zeros(n, jnp.int32),
            jnp.full(n, speed),
            jnp.full(n, RADIUS, position.dtype),
            alive,
            jnp.where(alive[:, None], velocity, 0.0),
            False,
        )
        setup = RolloutSetup(batch.world, peds, steps=batch.steps, dt=DT)
        rp = RolloutParams(
            params,
            jnp.full(n, speed),
            batch.world.walls,
            jnp.zeros((0,), position.dtype),
            jnp.asarray(1.0, position.dtype),
        )
        traj = rollout(rp, setup)
        return traj.position[-1], traj.overflow

    end, overflow = jax.vmap(one)(batch.position, batch.velocity, batch.alive)
    return end, jnp.max(overflow)


def window_residuals(
    names: Sequence[str],
    values: Float[Array, " P"],
    batch: WindowBatch,
    base: AvoidanceParams | None = None,
) -> Float[Array, " W"]:
    """Per window: the simulated minus the measured mean speed (m/s) over the horizon of the
    people counted (module docstring); 0 where nobody is counted."""
    params, speed = parameter_values(names, values, AvoidanceParams() if base is None else base)
    end, _ = _end_positions(params, speed, batch)
    horizon = batch.steps * DT

    def speeds(at: Array) -> Array:
        d = at - batch.position
        return jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-12) / horizon

    w = batch.counted.astype(values.dtype)
    diff = jnp.sum(w * (speeds(end) - speeds(batch.end)), axis=1)
    return diff / jnp.maximum(jnp.sum(w, axis=1), 1.0)


@dataclass(frozen=True)
class Calibration:
    """A fit's outcome.

    Attributes:
        names: the fitted parameters.
        start, values: their values at the start and fitted.
        rms_start, rms: the windows' residual RMS (m/s) at the start and at the fit.
        steps: Levenberg–Marquardt steps taken.
        converged: optimistix reported success.
        singular_values: of the residuals' Jacobian in the log-parameters at the fit (how well
            each direction is determined; a tiny one is a direction the data do not fix).
    """

    names: tuple[str, ...]
    start: np.ndarray
    values: np.ndarray
    rms_start: float
    rms: float
    steps: int
    converged: bool
    singular_values: np.ndarray


def _all_residuals(
    log_values: Array, batches: tuple[WindowBatch, ...], names: tuple[str, ...]
) -> Array:
    values = jnp.exp(log_values)
    return jnp.concatenate([window_residuals(names, values, b) for b in batches])


def _fn(y: Array, args: tuple[tuple[WindowBatch, ...], tuple[str, ...]]) -> Array:
    """The residuals in the log-parameters; one function object, so optimistix's compiled
    solve is reused across calls with batches of the same shapes."""
    return _all_residuals(y, *args)


def calibrate(
    batches: Sequence[WindowBatch],
    start: dict[str, float],
    *,
    max_steps: int = 40,
    rtol: float = 1e-4,
    atol: float = 1e-5,
) -> Calibration:
    """Fit the parameters named in ``start`` (from those values) to every batch's windows by
    Levenberg–Marquardt on their logarithms (module docstring).

    Raises:
        JcrowdError: unknown or repeated names, a start value that is not positive and finite,
            or no batch.
    """
    names = tuple(start)
    _check_names(names)
    x0 = np.array([start[n] for n in names], np.float64)
    if not np.all(np.isfinite(x0) & (x0 > 0)):
        raise JcrowdError(f"calibrate: expected positive start values, found {start}")
    if not batches:
        raise JcrowdError("calibrate: expected at least one run's windows, found none")
    group = tuple(batches)
    y0 = jnp.log(jnp.asarray(x0, jnp.float32))

    args = (group, names)
    solver: Any = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol: Any = optx.least_squares(_fn, solver, y0, args, max_steps=max_steps, throw=False)
    r0, r1 = _fn(y0, args), _fn(sol.value, args)
    jac = jax.jacfwd(_fn)(sol.value, args)
    return Calibration(
        names,
        x0,
        np.exp(np.asarray(sol.value, np.float64)),
        float(jnp.sqrt(jnp.mean(r0**2))),
        float(jnp.sqrt(jnp.mean(r1**2))),
        int(sol.stats["num_steps"]),
        bool(sol.result == optx.RESULTS.successful),
        np.linalg.svd(np.asarray(jac, np.float64), compute_uv=False),
    )
