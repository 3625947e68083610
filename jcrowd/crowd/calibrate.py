"""Calibrating the pedestrian dynamics to measured trajectories, by gradient (issue 22, item 2).

The collision-free speed model's parameters (:class:`~jcrowd.crowd.avoidance.AvoidanceParams`),
the body radius ``r`` and the free walking speed ``v0`` are fitted to measured runs by
Levenberg–Marquardt (optimistix) through differentiable rollouts (:mod:`jcrowd.crowd.rollout`),
started at the best point of a coarse grid.

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
  (10² in the free-flow ``uo-050-180-180``), at 0.5 s it stays bounded; at 1.0 s it
  reached 3.3·10³ and Levenberg–Marquardt stayed at its start.
- **What is compared: every person's velocity** (``residual="person"``, the default). Per
  window and per person who starts in the run's measurement area, the simulated minus the
  measured mean velocity over the horizon (the end positions' difference ÷ ``horizon_s``; both
  components, m/s; 0 for everyone else). The alternative ``residual="speed"`` compares one
  number per window, the counted people's mean speed. Per person is what fixes the body
  radius: with mean speeds the windows determine only a combination of ``T`` and ``r`` — the
  best ``T`` runs from 0.28 s at ``r`` = 0.2 m to 0.49 s at 0.15 m along a valley whose RMS
  changes by 7 % (0.146–0.157 m/s), and a (``T``, ``r``) fit from (0.78, 0.26) stopped at
  (0.12 s, 0.22 m), whose free run is far off (fundamental-diagram speed RMSE 0.179 m/s). A mean
  lets one person's error cancel another's; per person it cannot, and the Jacobian's smaller
  singular value rises from 6.6 to 11.
- **What is fitted: ``T`` and ``r``** (:data:`DEFAULT_NAMES`). ``ℓ = r_i + r_j`` is the spacing
  at which people stop (Eq. 2), the width of the corridor ahead (Eq. 3) and the repulsion's
  reach (Eq. 4); JuPedSim's default ``r`` = 0.2 m is half a shoulder width, but the tracked
  heads come closer than that (in the densest run 5 % of nearest-neighbour distances are under
  0.31 m; the entrance experiment's crowd stood 0.27 m centre to centre,
  ``examples/entrance.toml``), and with ``r`` fixed at 0.2 m the windows could only ask for a
  short ``T`` (0.28 s), which let the corridor without a bottleneck (``uo-180-180-180``) carry
  the measured flow at a lower density and a higher speed than the congested crowd measured
  there (fundamental-diagram speed RMSE 0.136–0.141 m/s, no better than the defaults' 0.138
  m/s).
- **Where the fit starts: the best point of a coarse grid** (:data:`COARSE_GRID`). The
  per-person objective has one broad valley, ``T`` rising as ``r`` falls, nearly flat along it
  (every 2 s, on a grid: RMS within 1.5 % from (0.48, 0.16) to (0.68, 0.13)), and ``r`` enters
  Eq. 3 through a hard set — who is in the corridor ahead — so the objective is a staircase in
  ``r`` that the pathwise derivative does not see: Levenberg–Marquardt's steps along the valley
  are rejected and it reports convergence on a step's edge (there the Jacobian's largest
  singular value was 2409 against 50 elsewhere). Started at the bench's three starts (×1.3,
  ×0.7, ×1.3/×0.7 of ``T`` = 0.6 s, ``r`` = 0.2 m), it ended at (0.387 s, 0.193 m), (0.598,
  0.143) and (0.627, 0.138): 35 % apart (row "calibrate — 2026-12-06 — code 441c356"; the same
  ×1.3 start reached (0.571, 0.148) in another process). So :func:`calibrate` first evaluates
  the residual RMS at the start and at every point of the grid (42 for ``T`` and ``r``: 61 s on
  2 cores, 1.07 s an evaluation of 268 windows) and starts from the least; the gradient then
  does the fitting (the grid's best, (0.66 s, 0.14 m) at RMS 0.0724 m/s, is 10 % from the fit
  in ``T``; started from its neighbours in ``T``, (0.42, 0.14) and (0.78, 0.14), the fit ends
  within 5 % of it, at (0.598, 0.143) and (0.627, 0.138): the grid's spacing does not decide
  the answer). That point beats each of the three starts (RMS 0.140, 0.080, 0.076), so all
  three give the same fit, (``T``, ``r``) = (0.602 s, 0.142 m) at RMS 0.0721, whose free run
  matches the fundamental diagram better than the defaults: speed RMSE 0.094 against 0.138 m/s
  (row "… code 9a0969a"). Reading taken: a global look at a two-parameter objective before a local
  fit is the usual cure for a rough one; a start still wins where it beats every grid point
  (a user's better guess is kept), and ``--no-search`` skips the grid. Tried and dropped: a
  profile in ``r`` (a 1 cm grid, ``T`` fitted by Levenberg–Marquardt at each): each 1-D fit
  took 14–15 steps even from its optimum (150–220 s), about 1.5 h a fit. On the model's own
  trajectories, where the valley is sharp, ``T``, ``r`` and ``v0`` are recovered from ±30 %
  without the grid (measured within 1 %; ``tests/test_calibrate.py`` bounds it at 5 %).
- **What else was tried.** Fitting ``desired_speed`` moves it to 1.46 m/s, faster than the
  free-flow runs' measured 1.34–1.39 m/s, and worsens the fundamental diagram (0.158–0.183
  m/s); adding ``plain_reaction_time`` is degenerate (``T`` → 0.005 s, ``τ`` → 1.4 s absorb
  the start's mismatch); the smooth ``V``'s ``sharpness`` barely moves the windows (mean
  residual RMS 0.287 → 0.271 m/s at ``n`` = 8, worse at 16). The repulsion's
  ``strength``/``range``, ``wall_strength`` and ``anisotropy`` move the residuals by less than
  1 % of ``T``'s effect (their columns of the Jacobian at the defaults); a fit of them is set
  by noise. Any field of :class:`~jcrowd.crowd.avoidance.AvoidanceParams`, ``radius`` and
  ``desired_speed`` may be named. Parameters are fitted as logarithms (each stays positive; a
  step is relative).
- **Structure held by the forward pass.** As in every rollout, who is the nearest neighbour
  ahead is decided by the forward pass and carries no gradient (:mod:`jcrowd.crowd.rollout`).

Geometry (:func:`corridor_scene`): the HERMES corridor of the shared data's README — walkable
``x ∈ [0, b]``, ``y ∈ [-4, 4]`` with the rooms before and after it, an exit of the run's width
centred in a 0.2 m wall at ``y = -4`` and the target 2.5 m behind it; the measurement area
``x ∈ [0, b]``, ``y ∈ [-2, 0]``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from jcrowd.crowd.avoidance import AvoidanceParams
from jcrowd.crowd.calibrate_windows import (
    DT,
    RADIUS,
    WindowBatch,
    corridor_scene,
    make_windows,
    merge_windows,
)
from jcrowd.crowd.dynamics import Pedestrians
from jcrowd.crowd.rollout import RolloutParams, RolloutSetup, rollout
from jcrowd.errors import JcrowdError

__all__ = [
    "DEFAULT_NAMES",
    "EXTRA_NAMES",
    "RADIUS_NAME",
    "RESIDUALS",
    "SPEED_NAME",
    "Calibration",
    "WindowBatch",
    "calibrate",
    "corridor_scene",
    "make_windows",
    "merge_windows",
    "parameter_values",
    "person_residuals",
    "window_residuals",
]

DEFAULT_NAMES = ("time_gap", "radius")
"""The parameters fitted by default (module docstring)."""

SPEED_NAME = "desired_speed"
"""The free walking speed ``v0`` (m/s), fitted beside the avoidance model's fields."""

RADIUS_NAME = "radius"
"""Every agent's body radius ``r`` (m; the size ``ℓ = r_i + r_j`` of Eq. 2–4), fitted beside the
avoidance model's fields."""

EXTRA_NAMES = (SPEED_NAME, RADIUS_NAME)
"""The fitted names that are not fields of :class:`~jcrowd.crowd.avoidance.AvoidanceParams`."""


def parameter_values(
    names: Sequence[str], values: Float[Array, " P"], base: AvoidanceParams
) -> tuple[AvoidanceParams, Float[Array, ""], Float[Array, ""]]:
    """``base`` with the named fields set to ``values``, the desired speed and the body radius
    (``names`` may hold ``desired_speed`` and ``radius``; without them, the crowd-dynamics
    bench's 1.34 m/s and 0.2 m)."""
    speed = jnp.asarray(1.34, values.dtype)
    radius = jnp.asarray(RADIUS, values.dtype)
    params = base
    for k, name in enumerate(names):
        if name == SPEED_NAME:
            speed = values[k]
        elif name == RADIUS_NAME:
            radius = values[k]
        else:
            params = eqx.tree_at(_field(name), params, values[k])
    return params, speed, radius


def _field(name: str) -> Callable[[AvoidanceParams], Array]:
    def get(p: AvoidanceParams) -> Array:
        return cast(Array, getattr(p, name))

    return get


def _check_names(names: Sequence[str]) -> None:
    fields = set(AvoidanceParams.__dataclass_fields__) | set(EXTRA_NAMES)
    bad = [n for n in names if n not in fields]
    if bad or not names or len(set(names)) != len(names):
        raise JcrowdError(
            f"calibrate: expected distinct parameter names among {sorted(fields)}, found "
            f"{list(names)}"
        )


def _end_positions(
    params: AvoidanceParams, speed: Float[Array, ""], radius: Float[Array, ""], batch: WindowBatch
) -> tuple[Float[Array, "W N 2"], Array]:
    n = batch.position.shape[1]

    def one(position: Array, velocity: Array, alive: Array) -> tuple[Array, Array]:
        peds = Pedestrians(
            position,
            jnp.zeros(n, jnp.int32),
            jnp.full(n, speed),
            jnp.full(n, radius, position.dtype),
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


def _simulated_ends(
    names: Sequence[str], values: Array, batch: WindowBatch, base: AvoidanceParams | None
) -> Float[Array, "W N 2"]:
    """Every window's crowd simulated over the horizon under the named values: where each
    person ends."""
    params, speed, radius = parameter_values(
        names, values, AvoidanceParams() if base is None else base
    )
    return _end_positions(params, speed, radius, batch)[0]


def window_residuals(
    names: Sequence[str],
    values: Float[Array, " P"],
    batch: WindowBatch,
    base: AvoidanceParams | None = None,
) -> Float[Array, " W"]:
    """Per window: the simulated minus the measured mean speed (m/s) over the horizon of the
    people counted (module docstring); 0 where nobody is counted."""
    end = _simulated_ends(names, values, batch, base)
    horizon = batch.steps * DT

    def speeds(at: Array) -> Array:
        d = at - batch.position
        return jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-12) / horizon

    w = batch.counted.astype(values.dtype)
    diff = jnp.sum(w * (speeds(end) - speeds(batch.end)), axis=1)
    return diff / jnp.maximum(jnp.sum(w, axis=1), 1.0)


def person_residuals(
    names: Sequence[str],
    values: Float[Array, " P"],
    batch: WindowBatch,
    base: AvoidanceParams | None = None,
) -> Float[Array, "W N 2"]:
    """Per window and person counted: the simulated minus the measured mean velocity (m/s,
    both components: the end positions' difference ÷ the horizon); 0 for everyone else
    (module docstring)."""
    end = _simulated_ends(names, values, batch, base)
    return jnp.where(batch.counted[..., None], (end - batch.end) / (batch.steps * DT), 0.0)


RESIDUALS = ("person", "speed")
"""What a window compares: every counted person's velocity (:func:`person_residuals`) or the
counted people's mean speed (:func:`window_residuals`)."""


COARSE_GRID: dict[str, tuple[float, ...]] = {
    "time_gap": tuple(round(float(t), 3) for t in np.geomspace(0.2, 1.2, 7)),
    RADIUS_NAME: (0.10, 0.14, 0.18, 0.22, 0.26, 0.30),
    SPEED_NAME: (1.0, 1.2, 1.4, 1.6, 1.8),
}
"""Where the fit looks before Levenberg–Marquardt (module docstring, "Where the fit starts"):
per parameter the values tried (``time_gap`` 0.2–1.2 s, ``radius`` 0.10–0.30 m, free speed
1.0–1.8 m/s); a fitted parameter not listed is tried at its start value only."""


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
        searched_from: where Levenberg–Marquardt started: the best of the coarse grid and the
            start (the start itself where the search is off).
        rms_searched: the residual RMS there (m/s).
    """

    names: tuple[str, ...]
    start: np.ndarray
    values: np.ndarray
    rms_start: float
    rms: float
    steps: int
    converged: bool
    singular_values: np.ndarray
    searched_from: np.ndarray
    rms_searched: float


def _all_residuals(
    log_values: Array, batches: tuple[WindowBatch, ...], names: tuple[str, ...], kind: str
) -> Array:
    values = jnp.exp(log_values)
    one = person_residuals if kind == "person" else window_residuals
    return jnp.concatenate([one(names, values, b).reshape(-1) for b in batches])


def _fn(y: Array, args: tuple[tuple[WindowBatch, ...], tuple[str, ...], str]) -> Array:
    """The residuals in the log-parameters; one function object, so optimistix's compiled solve
    is reused across calls with batches of the same shapes."""
    return _all_residuals(y, *args)


@eqx.filter_jit
def _rms(y: Array, args: tuple[tuple[WindowBatch, ...], tuple[str, ...], str]) -> Array:
    return jnp.sqrt(jnp.mean(_fn(y, args) ** 2))


def calibrate(
    batches: Sequence[WindowBatch],
    start: dict[str, float],
    *,
    max_steps: int = 100,
    rtol: float = 1e-4,
    atol: float = 1e-5,
    residual: str = "person",
    grid: Mapping[str, Sequence[float]] | None = COARSE_GRID,
) -> Calibration:
    """Fit the parameters named in ``start`` to every batch's windows: the residual RMS at every
    point of ``grid`` (its values for the named parameters, each combination; ``None``: no
    search) and at ``start``, then Levenberg–Marquardt on the logarithms from the best of them
    (module docstring); ``residual`` is one of :data:`RESIDUALS`.

    Raises:
        JcrowdError: unknown or repeated names, a start or grid value that is not positive and
            finite, no batch, or an unknown ``residual``.
    """
    names = tuple(start)
    _check_names(names)
    if residual not in RESIDUALS:
        raise JcrowdError(f"calibrate: expected residual in {RESIDUALS}, found {residual!r}")
    x0 = np.array([start[n] for n in names], np.float64)
    if not np.all(np.isfinite(x0) & (x0 > 0)):
        raise JcrowdError(f"calibrate: expected positive start values, found {start}")
    grid = {n: grid[n] for n in names if n in grid} if grid else {}
    axes = [tuple(grid[n]) if n in grid else (start[n],) for n in names]
    for name, values in zip(names, axes, strict=True):
        a = np.asarray(values, np.float64)
        if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a) & (a > 0)):
            raise JcrowdError(
                f"calibrate: grid[{name!r}]: expected positive values, found {values}"
            )
    if not batches:
        raise JcrowdError("calibrate: expected at least one run's windows, found none")
    args = (tuple(batches), names, residual)
    y0 = jnp.log(jnp.asarray(x0, jnp.float32))
    rms_start = float(_rms(y0, args))
    points = itertools.product(*axes) if grid else ()  # no grid for any name: the start only
    ys = [y0, *(jnp.log(jnp.asarray(p, jnp.float32)) for p in points)]
    rms = [rms_start, *(float(_rms(y, args)) for y in ys[1:])]
    # The first of equals (the start when it ties); a point whose rollout is not finite loses.
    best = int(np.argmin(np.where(np.isfinite(rms), rms, np.inf)))
    solver: Any = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol: Any = optx.least_squares(_fn, solver, ys[best], args, max_steps=max_steps, throw=False)
    jac = jax.jacfwd(_fn)(sol.value, args)
    return Calibration(
        names,
        x0,
        np.exp(np.asarray(sol.value, np.float64)),
        rms_start,
        float(_rms(sol.value, args)),
        int(sol.stats["num_steps"]),
        bool(sol.result == optx.RESULTS.successful),
        np.linalg.svd(np.asarray(jac, np.float64), compute_uv=False),
        np.exp(np.asarray(ys[best], np.float64)),
        rms[best],
    )
