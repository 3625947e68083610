"""Windows of measured runs for the calibration (:mod:`jcrowd.rollouts.calibrate`): the HERMES
corridor's geometry, and every few seconds of a run's steady state the measured people as a
rollout's start, with where they were measured a horizon later.

The module docstring of :mod:`jcrowd.rollouts.calibrate` says why short windows from measured
states (and not free runs) and what is compared. Positions ``[x, y]`` of the recordings in
metres (people walk towards −y), time in seconds, the step ``DT`` = 1/30 s.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import shapely
from jaxtyping import Array, Bool, Float
from shapely.ops import nearest_points

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.world import World, build_world

__all__ = [
    "DT",
    "RADIUS",
    "VELOCITY_S",
    "WindowBatch",
    "corridor_scene",
    "make_windows",
    "merge_windows",
]

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


def _window_people(
    rows: np.ndarray,
    start: int,
    vf: int,
    h: int,
    fps: float,
    inner: shapely.Geometry,
    box: tuple[float, float, float, float],
) -> tuple[np.ndarray, ...]:
    """The people present at frame ``start``: start positions (moved just inside the walls),
    velocities over the ``vf`` frames before, measured positions ``h`` frames later (their
    start where they vanish), whether each is counted (in the measurement area ``box`` and
    still seen at the end) and the measured start positions."""
    x0, x1, y0, y1 = box
    now, before, later = (_positions_at(rows, f) for f in (start, start - vf, start + h))
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
    return p0, v0.reshape(-1, 2), end, counted, start_xy


def make_windows(
    rows: np.ndarray,
    fps: float,
    frames: tuple[int, int],
    corridor_m: float,
    exit_m: float,
    *,
    horizon_s: float = 0.5,
    every_s: float = 1.0,
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
    area, target, box = corridor_scene(corridor_m, exit_m)
    inner = area.buffer(-RADIUS - 0.02)
    per = [_window_people(rows, int(s), vf, h, fps, inner, box) for s in starts]
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
    world = build_world(area, [target])
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
