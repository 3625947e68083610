"""The layout optimiser: projected descent along a gradient's direction, judged by values.

:func:`projected_gradient`, descent along the gradient's direction projected
on the box, in coordinates scaled to the unit box, with step lengths in box units that grow
after a success and shrink after a failure, judged by the forward objective (the gradient's
magnitude is not used: in a jam it is off by orders of magnitude). Chosen over optimistix's
minimisers because the world is rebuilt on the host between iterates (a host loop, not one
compiled solve) and the box is the only constraint.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from jcrowd.errors import JcrowdError

__all__ = ["OptimizeResult", "projected_gradient"]


@dataclass(frozen=True)
class OptimizeResult:
    """What :func:`projected_gradient` found.

    Attributes:
        x: the best point evaluated (``θ``).
        value: the objective there.
        gradient: its gradient there.
        path: every point evaluated and its value, in order.
        evaluations: calls of the value-and-gradient function.
        iterations: accepted steps.
        message: why it stopped.
    """

    x: np.ndarray
    value: float
    gradient: np.ndarray
    path: tuple[tuple[np.ndarray, float], ...]
    evaluations: int
    iterations: int
    message: str


def projected_gradient(
    fun: Callable[[np.ndarray], tuple[float, np.ndarray]],
    x0: Sequence[float] | np.ndarray,
    lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
    *,
    max_evaluations: int = 8,
    tol: float = 1e-2,
    first_step: float = 0.25,
    longest_step: float = 0.5,
    shrink: float = 0.3,
) -> OptimizeResult:
    """Minimise ``fun`` (``x → (value, gradient)``) over the box ``lower ≤ x ≤ upper``.

    Descent along the gradient's direction projected on the box, in coordinates scaled to the
    unit box (``u = (x − lower)/(upper − lower)``): the trial point is
    ``clip(u − h g/‖g‖_∞, 0, 1)``, so the step length ``h`` is in box units (``first_step`` at
    first) and the gradient's magnitude is not used — in a jam it is off by many orders
    (module docstring) while its direction may still say where to look. A trial that lowers
    the value is kept and the next step is twice as long (at most ``longest_step``); one that
    does not is dropped and ``h`` multiplied by ``shrink``. Each trial calls ``fun`` once,
    except one within ``tol`` of a point already evaluated (it shrinks ``h`` at once).

    Stops when the projected step is shorter than ``tol`` (box units), when the gradient is not
    finite, or after ``max_evaluations`` calls; returns the best point seen.

    Raises:
        JcrowdError: bounds with ``lower ≥ upper``, a start outside them, or a budget below 1.
    """
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    x = np.asarray(x0, np.float64)
    if not (lo.shape == hi.shape == x.shape and np.all(lo < hi)):
        raise JcrowdError(f"optimiser: expected lower < upper of one shape, found {lo} and {hi}")
    if not np.all((lo <= x) & (x <= hi)):
        raise JcrowdError(f"optimiser: expected a start within [{lo}, {hi}], found {x}")
    if max_evaluations < 1:
        raise JcrowdError(
            f"optimiser: expected a budget of ≥ 1 evaluation, found {max_evaluations}"
        )
    span = hi - lo
    u = (x - lo) / span
    value, grad = fun(x)
    g = np.asarray(grad, np.float64) * span  # the gradient in box units
    path = [(x.copy(), float(value))]
    best = (x.copy(), float(value), np.asarray(grad, np.float64))
    evaluations, iterations, message = 1, 0, f"stopped after {max_evaluations} evaluations"
    step = first_step
    while evaluations < max_evaluations:
        if not np.all(np.isfinite(g)):
            message = "stopped: the gradient is not finite (a jam? module docstring)"
            break
        gmax = float(np.max(np.abs(g)))
        trial = np.clip(u - step * g / gmax, 0.0, 1.0) if gmax > 0 else u
        if float(np.max(np.abs(trial - u))) < tol:
            message = f"converged: projected step below {tol:g} of the box"
            break
        xt = lo + trial * span
        if any(np.max(np.abs(xt - p) / span) < tol for p, _ in path):
            step *= shrink  # evaluated already (and not kept): a shorter step, no call
            continue
        vt, gt = fun(xt)
        evaluations += 1
        path.append((xt.copy(), float(vt)))
        if np.isfinite(vt) and vt < value:
            best = (xt.copy(), float(vt), np.asarray(gt, np.float64))
            u, value, g = trial, float(vt), np.asarray(gt, np.float64) * span
            step = min(2.0 * step, longest_step)
            iterations += 1
        else:
            step *= shrink
    return OptimizeResult(best[0], best[1], best[2], tuple(path), evaluations, iterations, message)
