"""Natural-mode tensors (paper 004 §2): actor × style × repetition, synthesis from mode rows.

The data of every sample (technical modes first) is arranged on a grid of natural modes; an
N-mode SVD of the result (:func:`jcrowd.tensor.algebra.hosvd` with per-mode ranks) gives one factor
per mode, and a new motion is synthesized from linear combinations of mode rows
(:func:`synthesize`). Same conventions as :mod:`jcrowd.tensor.algebra` (NumPy float64, offline).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import TensorError
from jcrowd.tensor.algebra import (
    Tucker,
    multi_mode_product,
)

__all__ = ["NaturalModeTensor", "natural_mode_tensor", "synthesize"]

Array = np.ndarray


@dataclass(frozen=True)
class NaturalModeTensor:
    """A data tensor with technical modes first and natural modes actor, style, repetition last.

    Attributes:
        tensor: ``(*sample_shape, A, S, R)``. Paper 004's Data Mode is ``sample_shape = (f·n,)``;
            its Frame × DOF split is ``sample_shape = (f, n)``.
        actors, styles: the labels along the actor and style modes, in first-seen order.
        counts: ``(A, S)`` observed repetitions per cell; slots past ``counts[a, s]`` are filled.
    """

    tensor: Array
    actors: tuple[Hashable, ...]
    styles: tuple[Hashable, ...]
    counts: Int[Array, "A S"]

    @property
    def sample_shape(self) -> tuple[int, ...]:
        return tuple(int(s) for s in self.tensor.shape[:-3])


def natural_mode_tensor(
    samples: Float[Array, " n *sample"],
    actors: Sequence[Hashable],
    styles: Sequence[Hashable],
    *,
    fill: str = "mean",
) -> NaturalModeTensor:
    """Arrange labelled samples into a data × actor × style × repetition tensor (004 §2.1).

    Repetitions of one (actor, style) cell take slots 0, 1, … in input order; R is the largest
    count. Real sessions leave gaps (an actor repeats a style two times, another three), so:

    - ``fill="mean"``: a missing repetition slot is the mean of that cell's observed
      repetitions. The cell mean is then unchanged, so synthesising the cell with uniform
      repetition weights returns exactly the observed mean, and the filled slots add no
      variance to the repetition mode. A cell with no sample at all has nothing honest to fill
      from and raises.
    - ``fill="require"``: any gap raises (a full grid is required).

    Args:
        samples: ``(n, *sample_shape)`` time-aligned samples (flatten for the Data Mode).
        actors, styles: ``n`` labels each.
    """
    samples = np.asarray(samples, dtype=np.float64)
    n = samples.shape[0] if samples.ndim else 0
    if samples.ndim < 2 or n == 0 or len(actors) != n or len(styles) != n:
        raise TensorError(
            f"natural modes: expected samples (n, ...) with n ≥ 1 and n actor and style labels, "
            f"found samples {samples.shape}, {len(actors)} actors, {len(styles)} styles"
        )
    if fill not in ("mean", "require"):
        raise TensorError(f'natural modes: expected fill "mean" or "require", found {fill!r}')
    actor_labels, style_labels = tuple(dict.fromkeys(actors)), tuple(dict.fromkeys(styles))
    a_index = [actor_labels.index(a) for a in actors]
    s_index = [style_labels.index(s) for s in styles]
    counts = np.zeros((len(actor_labels), len(style_labels)), dtype=np.int32)
    for a, s in zip(a_index, s_index, strict=True):
        counts[a, s] += 1
    reps = int(counts.max())
    empty = [(actor_labels[a], style_labels[s]) for a, s in np.argwhere(counts == 0)]
    if empty or (fill == "require" and np.any(counts != reps)):
        what = f"cells with no sample: {empty}" if empty else f"repetition counts {counts.tolist()}"
        raise TensorError(f"natural modes ({fill=}): expected every cell filled, found {what}")
    T = np.zeros((*samples.shape[1:], *counts.shape, reps))
    slot = np.zeros_like(counts)
    for i, (a, s) in enumerate(zip(a_index, s_index, strict=True)):
        T[..., a, s, slot[a, s]] = samples[i]
        slot[a, s] += 1
    for a, s in np.argwhere(counts < reps):
        T[..., a, s, counts[a, s] :] = T[..., a, s, : counts[a, s]].mean(axis=-1, keepdims=True)
    return NaturalModeTensor(T, actor_labels, style_labels, counts)


def _mode_row(U: Array, weight: int | Sequence[float] | Array | None, name: str) -> Array:
    """``wᵀ U`` (a length-R row) for a weight over the mode's entries; None = uniform mean."""
    size = U.shape[0]
    if weight is None:
        w = np.full(size, 1.0 / size)
    elif isinstance(weight, int | np.integer):
        if not 0 <= weight < size:
            raise TensorError(f"synthesize: expected a {name} index in [0, {size}), found {weight}")
        w = np.eye(size)[weight]
    else:
        w = np.asarray(weight, dtype=np.float64)
        if w.shape != (size,):
            raise TensorError(f"synthesize: expected {size} {name} weights, found {w.shape}")
    return w @ U


def synthesize(
    model: Tucker,
    actor: int | Sequence[float] | Array | None = None,
    style: int | Sequence[float] | Array | None = None,
    repetition: int | Sequence[float] | Array | None = None,
) -> Array:
    """A motion from linear combinations of natural-mode rows (paper 004 §2.3).

    ``y = Z ×_tech U_tech ×_actor (w_aᵀ U_a) ×_style (w_sᵀ U_s) ×_rep (w_rᵀ U_r)``: the technical
    modes are multiplied out and each natural mode contributes one row mixed from its factor's
    rows. Each weight is an index (one original actor/style/repetition), a weight vector over
    that mode's entries (weights summing to 1 interpolate, e.g. a new actor as 0.3·A + 0.7·B),
    or ``None`` for the uniform mean over the mode.

    Args:
        model: N-mode SVD of a :class:`NaturalModeTensor` (``hosvd(nm.tensor, ranks)``).
    Returns:
        ``sample_shape`` array.
    """
    if model.core.ndim < 4:
        raise TensorError(
            f"synthesize: expected ≥ 1 technical + 3 natural modes, found {model.core.ndim} modes"
        )
    *tech, Ua, Us, Ur = model.factors
    rows = [
        _mode_row(Ua, actor, "actor"),
        _mode_row(Us, style, "style"),
        _mode_row(Ur, repetition, "repetition"),
    ]
    y = multi_mode_product(model.core, [*tech, *(r[None, :] for r in rows)])
    return y.reshape(y.shape[:-3])
