"""Calibrating the pedestrian model to measured trajectories, by gradient.

The model's parameters (:class:`~jcrowd.pedestrians.params.AvoidanceParams`), the body radius
``r`` and the free walking speed ``v0`` are fitted to measured runs by Levenberg–Marquardt
(optimistix) through differentiable rollouts (:mod:`jcrowd.rollouts.rollout`), started at the
best point of a coarse grid. Parameters are fitted as logarithms (positive; relative steps).

Readings taken, and why (docs/design/rollouts.md has the measurements):

- **Short windows from measured states** (:mod:`jcrowd.rollouts.windows`): every ``every_s``
  seconds of a run's steady state, everyone present is placed where they were measured with
  their measured velocity and the crowd is simulated ``horizon_s`` = 0.5 s. A whole run cannot
  be differentiated (its jams make the derivative grow ×1.4 per step); a prediction from the
  measured state is the usual trajectory-based calibration of microscopic models, and at 0.5 s
  the Jacobian stays bounded where at 1–1.5 s it reached 10³–10⁴.
- **Every person's velocity is compared** (``residual="person"``, the default): per window and
  per person starting in the measurement area, simulated minus measured mean velocity over the
  horizon. One mean speed per window (``residual="speed"``) lets one person's error cancel
  another's and fixes only a combination of ``T`` and ``r``.
- **``T`` and ``r`` are fitted** (:data:`DEFAULT_NAMES`): ``ℓ = r_i + r_j`` sets where people
  stop (Eq. 2), the corridor ahead (Eq. 3) and the repulsion's reach (Eq. 4), and the tracked
  heads come closer than JuPedSim's ``r`` = 0.2 m. Fitting ``v0``, the reaction time or the
  repulsion's terms is allowed (any field, ``radius``, ``desired_speed``) but not the default.
- **The fit starts at the best point of a coarse grid** (:data:`COARSE_GRID`, or the start if
  that is better; ``--no-search`` skips it). The per-person objective has one flat valley and
  ``r`` enters Eq. 3 through a hard set, so it is a staircase in ``r`` that the pathwise
  derivative does not see; Levenberg–Marquardt alone stops on a step's edge, different ones
  from different starts. A global look before a local fit is the usual cure.
- **Structure held by the forward pass**: who is nearest ahead carries no gradient
  (:mod:`jcrowd.rollouts.rollout`).

``bench/calibrate.py`` runs the fit on the HERMES corridor runs from three starts and compares
the fitted model's fundamental diagram with the defaults'; ``tests/test_calibrate.py`` recovers
``T``, ``r`` and ``v0`` from ±30 % on the model's own trajectories.
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

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.step import Pedestrians
from jcrowd.rollouts.rollout import RolloutParams, RolloutSetup, rollout
from jcrowd.rollouts.windows import (
    DT,
    RADIUS,
    WindowBatch,
)

__all__ = [
    "DEFAULT_NAMES",
    "EXTRA_NAMES",
    "RADIUS_NAME",
    "RESIDUALS",
    "SPEED_NAME",
    "Calibration",
    "calibrate",
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
"""The fitted names that are not fields of :class:`~jcrowd.pedestrians.params.AvoidanceParams`."""


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
def _jacobian(y: Array, args: tuple[tuple[WindowBatch, ...], tuple[str, ...], str]) -> Array:
    """``∂ residuals / ∂ log-parameters``, compiled once per batch shapes (run op by op, the
    rollout's scan would compile anew at every call)."""
    return jax.jacfwd(_fn)(y, args)


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
    jac = _jacobian(sol.value, args)
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
