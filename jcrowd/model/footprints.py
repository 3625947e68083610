"""Footprints → controls: the controls whose synthesized cycle plants the feet where asked.

Paper 001 §5.3 (Fig. 12) drives a gait by "the footprints of both feet as 4D control
parameters": its samples are kriged over the footprints themselves. jcrowd's models are kriged
over the cycle's root displacement and turn ``(dx, dz, dyaw)`` (:mod:`jcrowd.model.motion_model`),
so a footprint query is answered the other way round: per gait cycle, solve for the controls
``c`` whose synthesized cycle puts its planted feet on the given footprints,

    min_c  ‖F(c) − F*‖²,   F(c) = footprints of FK(decode(U_P K(c) U_Tᵀ))       (1)

by Levenberg–Marquardt (optimistix) through the kriging weights ``b(c)`` (000 Eq. 8), the
pose-vector decode and forward kinematics, all differentiated by JAX. Every query is clamped to
the model's control range before kriging, as :func:`~jcrowd.model.motion_model.synthesize_clip`
does; inside the solve the clamp is part of (1), so a coordinate pressed against its bound
stays there.

A cycle's footprints are ``(3, 2)``: the ``[x, z]`` (m) of the ankle (the heel) of the left
foot at the opening heel strike, the right foot at its strike and the left foot at the closing
strike; only their positions relative to the opening footprint are matched. With
``heading=None`` each cycle's footprints are in its own start frame (+Z ahead, x to the
character's left); with ``heading=θ`` they are world positions and cycle ``k + 1`` starts
facing where cycle ``k``'s synthesized clip ends. ``F(c)`` (:mod:`jcrowd.model.footprint_map`)
reads the model's own cycle at fixed aligned frames, without foot locking;
:func:`footprint_errors` measures the delivered clip as a capture is measured.

The *forward rule* it is compared with takes ``(dx, dz)`` from the left foot's displacement
over the cycle and ``dyaw = 2·atan2(dx, dz)``, the turn of a constant-curvature path with that
chord; it ignores the right footprint and the foot's offset from the root, which turns with the
body. Why solve: on cycles of cmu16 takes held back from the fit, the solved controls plant the
feet 3.4 cm from the footprints on average against 12.0 cm by the forward rule, and 5.4 against
22.9 cm on turning cycles (``bench/footprints.py``). The readings taken for the footprint
format, the frames and the strike frames are in ``docs/design/model.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np

from jcrowd.errors import KrigingError
from jcrowd.model.footprint_map import (
    FootprintMap,
    cycle_footprints,
    footprint_map,
    relative_batch,
    solve_jit,
    synthesized_jit,
)
from jcrowd.model.motion_model import MotionModel, synthesize_clip

__all__ = [
    "FootprintControls",
    "controls_for_footprints",
    "cycle_footprints",
    "footprint_errors",
    "footprints_for_controls",
    "forward_rule_controls",
]


@dataclass(frozen=True)
class FootprintControls:
    """Solved and forward-rule controls for a run of cycles.

    Attributes:
        controls: ``(N, d)`` the solved controls (in the model's range), in
            ``model.control_names`` order.
        forward: ``(N, d)`` the forward rule's controls (clamped to the range).
        error_m: ``(N,)`` mean distance (m) of the right and closing left footprints of the
            model's cycle at ``controls`` from the asked ones, relative to the opening footprint
            (the objective (1) as distances).
        forward_error_m: ``(N,)`` the same at ``forward``.
        headings: ``(N,)`` each cycle's start heading (radians; 0 without ``heading``).
        converged: ``(N,)`` whether Levenberg–Marquardt met its tolerance within its steps.
        steps: ``(N,)`` Levenberg–Marquardt steps taken.
    """

    controls: np.ndarray
    forward: np.ndarray
    error_m: np.ndarray
    forward_error_m: np.ndarray
    headings: np.ndarray
    converged: np.ndarray
    steps: np.ndarray


def _rotate(xz: np.ndarray, angle: float) -> np.ndarray:
    """``[x, z]`` rows turned by ``angle`` about +Y (+ turns +z towards +x)."""
    s, c = np.sin(angle), np.cos(angle)
    return np.stack([c * xz[..., 0] + s * xz[..., 1], -s * xz[..., 0] + c * xz[..., 1]], axis=-1)


def forward_rule_controls(
    model: MotionModel, footprints: np.ndarray, *, height: float | None = None
) -> np.ndarray:
    """The forward rule's controls ``(N, d)`` for start-frame footprints ``(N, 3, 2)`` (module doc).

    Clamped to the model's range, as synthesis clamps them.
    """
    fp = _check_footprints(footprints)
    h = _height(model, height)
    d = fp[:, 2] - fp[:, 0]
    values = {
        "dx": d[:, 0],
        "dz": d[:, 1],
        "dyaw": 2.0 * np.arctan2(d[:, 0], d[:, 1]),
        "height": np.full(len(fp), h),
    }
    median = np.median(np.asarray(model.levels[0].kriging.controls, np.float64), axis=0)
    cols = [
        values.get(name, np.full(len(fp), median[k])) for k, name in enumerate(model.control_names)
    ]
    c = np.stack(cols, axis=-1)
    return np.clip(c, model.control_ranges[:, 0], model.control_ranges[:, 1])


def footprints_for_controls(
    model: MotionModel,
    controls: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
    heading: float | None = None,
    origin: np.ndarray | None = None,
) -> np.ndarray:
    """The model's footprints ``(N, 3, 2)`` for controls ``(N, d)`` — the map (1), chained.

    Without ``heading``: every cycle in its own start frame (root above the origin facing +Z).
    With ``heading`` (and ``origin``, the first opening footprint in the world, default 0): the
    cycles follow each other as :func:`controls_for_footprints` chains them — each starts with
    its left foot on the previous cycle's closing footprint, facing where that cycle ended.
    """
    _check_level(model, level)
    c = np.asarray(controls, np.float64)
    if c.ndim != 2 or c.shape[1] != len(model.control_names) or not np.all(np.isfinite(c)):
        raise KrigingError(
            f"footprints: expected finite controls of shape (N, {len(model.control_names)}) "
            f"{model.control_names}, found shape {c.shape}"
        )
    fmap = footprint_map(model, level, _height(model, height))
    out: list[np.ndarray] = []
    theta = 0.0 if heading is None else float(heading)
    at = np.zeros(2) if origin is None else np.asarray(origin, np.float64).reshape(2)
    for row in c:
        got, end = synthesized_jit(fmap, jnp.asarray(row, fmap.u_pose.dtype))
        fp = np.asarray(got, np.float64)
        if heading is None:
            out.append(fp)
            continue
        world = at + _rotate(fp - fp[0], theta)
        out.append(world)
        at, theta = world[2], theta + float(end)
    return np.stack(out)


def controls_for_footprints(
    model: MotionModel,
    footprints: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
    heading: float | None = None,
    max_steps: int = 64,
) -> FootprintControls:
    """Controls per cycle whose synthesized cycle plants the feet on ``footprints`` (module doc).

    Args:
        model: a fitted model kriged over ``dx`` and ``dz`` (and usually ``dyaw``).
        footprints: ``(N, 3, 2)`` per cycle the ``[x, z]`` (m) of the opening left, the right and
            the closing left footprint; in each cycle's start frame, or in the world with
            ``heading``.
        level: the model level whose cycle is matched.
        height: the character's height (m); default as in
            :func:`~jcrowd.model.motion_model.synthesize_clip`. A ``height`` control is held at it.
        heading: ``None`` (each cycle in its own start frame, cycles independent) or cycle 0's
            start heading in the world (radians; each cycle starts where the last one ended).
        max_steps: Levenberg–Marquardt steps per cycle.

    Returns:
        :class:`FootprintControls`: the solution (1), started from and compared with the forward
        rule. Paper 001 §5.3 (Fig. 12).
    """
    _check_level(model, level)
    fp = _check_footprints(footprints)
    for name in ("dx", "dz"):
        if name not in model.control_names:
            raise KrigingError(
                f"footprints: expected a model kriged over dx and dz, found controls "
                f"{model.control_names}"
            )
    if heading is not None and not np.isfinite(heading):
        raise KrigingError(f"footprints: expected a finite heading (radians), found {heading}")
    h = _height(model, height)
    fmap = footprint_map(model, level, h)
    dtype = fmap.u_pose.dtype
    free = jnp.asarray([n != "height" for n in model.control_names])
    rows, fwd_rows, flags, counts, starts = [], [], [], [], []
    theta = 0.0 if heading is None else float(heading)
    for cycle in fp:
        # Start frame of this cycle: its own (no heading), or where the previous one ended.
        local = _rotate(cycle - cycle[0], -theta)
        start = forward_rule_controls(model, local[None], height=h)[0]
        target = jnp.asarray(local[1:] - local[:1], dtype)
        c, ok, steps = solve_jit(fmap, target, jnp.asarray(start, dtype), free, max_steps)
        rows.append(np.asarray(c, np.float64))
        fwd_rows.append(start)
        flags.append(bool(ok))
        counts.append(int(steps))
        starts.append(theta)
        if heading is not None:
            theta += float(synthesized_jit(fmap, c)[1])
    solved, forward, headings = np.stack(rows), np.stack(fwd_rows), np.array(starts)
    local_all = np.stack([_rotate(f - f[0], -t) for f, t in zip(fp, headings, strict=True)])
    return FootprintControls(
        solved,
        forward,
        _errors(fmap, solved, local_all),
        _errors(fmap, forward, local_all),
        headings,
        np.array(flags, bool),
        np.array(counts, np.int64),
    )


def footprint_errors(
    model: MotionModel,
    controls: np.ndarray,
    footprints: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
) -> np.ndarray:
    """Planted-foot error (m) per cycle of the *delivered* clips at ``controls`` ``(N, d)``.

    Each cycle is synthesized as the user gets it (:func:`synthesize_clip`: decode, unwarp to
    the model clock, no foot locking) and its footprints are read the way a capture's are
    (:func:`cycle_footprints`: contact detection, ankle at each heel strike); the error is the
    mean distance of its right and closing left footprints from the asked start-frame
    ``footprints`` ``(N, 3, 2)``, both relative to their opening left footprint. Independent of
    the solver's fixed aligned frames and interpolation.
    """
    fp = _check_footprints(footprints)
    c = np.asarray(controls, np.float64)
    if c.shape != (len(fp), len(model.control_names)):
        raise KrigingError(
            f"footprint errors: expected controls of shape ({len(fp)}, "
            f"{len(model.control_names)}) for {len(fp)} cycles, found {c.shape}"
        )
    out = []
    for row, want in zip(c, fp, strict=True):
        got, _ = cycle_footprints(synthesize_clip(model, row.tolist(), level, height=height))
        miss = (got[1:] - got[:1]) - (want[1:] - want[:1])
        out.append(float(np.linalg.norm(miss, axis=-1).mean()))
    return np.array(out)


def _errors(fmap: FootprintMap, controls: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Mean footprint distance (m) of the model's cycles at ``controls`` from ``local``."""
    got = relative_batch(fmap, jnp.asarray(controls, fmap.u_pose.dtype))
    want = local[:, 1:] - local[:, :1]
    return np.linalg.norm(np.asarray(got, np.float64) - want, axis=-1).mean(axis=-1)


def _check_level(model: MotionModel, level: int) -> None:
    if not 0 <= level < len(model.levels):
        raise KrigingError(
            f"footprints: expected a level in 0..{len(model.levels) - 1}, found {level}"
        )


def _height(model: MotionModel, height: float | None) -> float:
    if height is None:
        return model.default_height
    if not np.isfinite(height) or height <= 0:
        raise KrigingError(f"footprints: expected a positive finite height (m), found {height}")
    return float(height)


def _check_footprints(footprints: Any) -> np.ndarray:
    fp = np.asarray(footprints, np.float64)
    if fp.ndim != 3 or fp.shape[1:] != (3, 2) or len(fp) == 0:
        raise KrigingError(
            "footprints: expected shape (N, 3, 2) — per cycle [x, z] of the opening left, the "
            f"right and the closing left footprint, N >= 1 — found {fp.shape}"
        )
    bad = np.argwhere(~np.isfinite(fp))
    if bad.size:
        raise KrigingError(
            f"footprints: expected finite [x, z], found {fp[tuple(bad[0])]} at cycle "
            f"{bad[0][0]}, footprint {bad[0][1]}"
        )
    return fp
