"""Leave-one-clip-out cross-validation of motion prediction: kriging vs RBF vs nearest sample.

Every gait cycle of a clip, and its mirror, leaves together (sibling cycles of one take are
near-duplicates and would flatter every method). For each left-out clip the remaining samples'
level-``l`` cores ``K_i`` are interpolated over the controls by universal kriging
(:mod:`jcrowd.kriging`), by the "verbs and adverbs" RBF (Rose et al.) and by the nearest sample,
and the predicted pose vectors ``U_P K(c) U_Tᵀ`` are compared with the left-out sample's own
(the tensor's data): mean joint position error in the root frame and end-of-cycle root
displacement error (m), averaged over the left-out samples.

Choices, stated: the tensor bases (HOOI on all samples) and the kriging variogram (fitted once on
all samples) are shared by the folds — refitting them per fold would cost a full fit per clip;
both leak equally into all three methods, so the comparison stays fair. RBF and nearest see
the same normalised controls as kriging.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from jcrowd.kriging.rbf import fit_rbf, predict_nearest, predict_rbf
from jcrowd.kriging.universal import fit_kriging, normalise_controls, predict
from jcrowd.model import sample_cores
from jcrowd.samples import CONTROL_NAMES
from jcrowd.tensor_model import TensorModel, _root_frame

__all__ = ["METHODS", "leave_one_clip_out"]

METHODS = ("kriging", "rbf", "nearest")


def leave_one_clip_out(
    tensor: TensorModel,
    controls: Sequence[str] = ("dx", "dz", "dyaw"),
    *,
    level: int = 0,
    methods: Sequence[str] = METHODS,
) -> dict[str, dict[str, float]]:
    """``{method: {"joint_m": ..., "root_m": ...}}`` over every left-out clip (module doc)."""
    lv = tensor.levels[level]
    u_p, u_t, u_s = lv.tucker.factors
    cores = sample_cores(lv.tucker.core, u_s)
    idx = [CONTROL_NAMES.index(c) for c in controls]
    c_all = tensor.controls[:, idx]
    c_norm, _, _ = normalise_controls(c_all)
    # Normalise once, so the variogram fitted on all samples keeps its units in every fold.
    variogram = fit_kriging(c_norm, cores, normalise=False).variogram
    truth = np.transpose(tensor.tensor, (2, 1, 0)) * tensor.layout.scale
    errors: dict[str, list[tuple[float, float]]] = {m: [] for m in methods}
    for group in np.unique(tensor.groups):
        out = tensor.groups == group
        train = ~out
        if np.count_nonzero(train) < len(idx) + 2:
            continue
        preds: dict[str, np.ndarray] = {}
        if "kriging" in methods:
            km = fit_kriging(c_norm[train], cores[train], variogram, normalise=False)
            preds["kriging"] = np.asarray(predict(km, jnp.asarray(c_norm[out], jnp.float32)))
        if "rbf" in methods:
            rm = fit_rbf(c_norm[train], cores[train])
            preds["rbf"] = np.asarray(predict_rbf(rm, jnp.asarray(c_norm[out], jnp.float32)))
        if "nearest" in methods:
            preds["nearest"] = np.asarray(
                predict_nearest(c_norm[train], cores[train], jnp.asarray(c_norm[out]))
            )
        for method, k in preds.items():
            y = (
                np.einsum("pr,srt,ut->sup", u_p, np.asarray(k, np.float64), u_t)
                * tensor.layout.scale
            )
            for j, s in enumerate(np.nonzero(out)[0]):
                h = float(tensor.heights[s])
                a = _root_frame(truth[s], tensor, h)
                b = _root_frame(y[j], tensor, h)
                errors[method].append(
                    (
                        float(np.linalg.norm(a[0] - b[0], axis=-1).mean()),
                        float(np.linalg.norm(a[1] - b[1])),
                    )
                )
    return {
        m: {
            "joint_m": float(np.mean([e[0] for e in v])),
            "root_m": float(np.mean([e[1] for e in v])),
        }
        for m, v in errors.items()
    }
