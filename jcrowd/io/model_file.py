"""``MotionModel`` files (``.jcm``): per level the bases, the kriging system and its variogram.

Stored with :mod:`jcrowd.io.store` (safetensors + JSON metadata, checksum, atomic write) under
the kind ``"motion-model"``. Every array of each level's
:class:`~jcrowd.kriging.universal.KrigingModel` is saved by its field name, so loading rebuilds
the same model bit for bit without refitting. The model's ``body_height`` is not stored: loading
measures it on the shipped body (:func:`jcrowd.io.body_file.with_body_height`).
"""

from __future__ import annotations

import os
from typing import Any

import jax.numpy as jnp
import numpy as np

from jcrowd.errors import StoreError
from jcrowd.io.body_file import with_body_height
from jcrowd.io.resources import default_model_path
from jcrowd.io.store import load_store, save_store, skeleton_from_json, skeleton_to_json
from jcrowd.kriging.universal import KrigingModel
from jcrowd.kriging.variogram_fit import VariogramFit
from jcrowd.model.motion_model import MotionLevel, MotionModel
from jcrowd.model.posevec import PoseLayout

__all__ = ["KIND", "load_default_model", "load_motion_model", "save_motion_model"]

KIND = "motion-model"

_KRIGING_ARRAYS = (
    "controls",
    "control_mean",
    "control_scale",
    "trend",
    "residuals",
    "gamma_operator",
    "drift_operator",
    "lagrange_gamma",
    "lagrange_drift",
    "dropped",
)


def save_motion_model(
    path: str | os.PathLike[str], model: MotionModel, *, extra: dict[str, Any] | None = None
) -> None:
    """Write ``model`` (and JSON-serialisable ``extra`` metadata, e.g. a fit report)."""
    tensors: dict[str, np.ndarray] = {
        "layout/reference": np.asarray(model.layout.reference),
        "layout/scale": np.asarray(model.layout.scale),
        "control_ranges": np.asarray(model.control_ranges),
    }
    levels = []
    for i, lv in enumerate(model.levels):
        tensors[f"level{i}/u_pose"] = np.asarray(lv.u_pose)
        tensors[f"level{i}/u_time"] = np.asarray(lv.u_time)
        k = lv.kriging
        for name in _KRIGING_ARRAYS:
            tensors[f"level{i}/kriging/{name}"] = np.asarray(getattr(k, name))
        for name in ("theta", "p", "result"):
            tensors[f"level{i}/variogram/{name}"] = np.asarray(getattr(k.variogram, name))
        levels.append(
            {"joints": list(lv.joints), "value_shape": list(k.value_shape), "system": k.system}
        )
    meta = {
        "skeleton": skeleton_to_json(model.skeleton),
        "control_names": list(model.control_names),
        "fps": model.fps,
        "default_height": model.default_height,
        "levels": levels,
        "extra": extra or {},
    }
    save_store(path, tensors, meta, kind=KIND)


def load_motion_model(path: str | os.PathLike[str]) -> tuple[MotionModel, dict[str, Any]]:
    """Read a model file: ``(model, extra metadata)``, checked as :func:`load_store` does."""
    t, meta = load_store(path, kind=KIND)
    try:
        skel = skeleton_from_json(meta["skeleton"])
        levels = []
        for i, info in enumerate(meta["levels"]):
            arrays = {n: jnp.asarray(t[f"level{i}/kriging/{n}"]) for n in _KRIGING_ARRAYS}
            # safetensors stores 0-d arrays as shape (1,): give the scalars their shape back.
            arrays["dropped"] = arrays["dropped"].reshape(())
            theta, p, result = (t[f"level{i}/variogram/{n}"] for n in ("theta", "p", "result"))
            vario = VariogramFit(
                jnp.asarray(theta), jnp.asarray(p).reshape(()), jnp.asarray(result).reshape(())
            )
            kriging = KrigingModel(
                **arrays,
                variogram=vario,
                value_shape=tuple(info["value_shape"]),
                system=info["system"],
            )
            levels.append(
                MotionLevel(
                    t[f"level{i}/u_pose"], t[f"level{i}/u_time"], kriging, tuple(info["joints"])
                )
            )
        model = MotionModel(
            skel,
            PoseLayout(skel.num_joints, t["layout/reference"], t["layout/scale"]),
            tuple(meta["control_names"]),
            t["control_ranges"],
            tuple(levels),
            float(meta["fps"]),
            float(meta["default_height"]),
        )
    except (KeyError, TypeError, ValueError) as e:
        raise StoreError(f"{path}: the motion-model contents are incomplete: {e}") from e
    return with_body_height(model), meta.get("extra", {})


def load_default_model() -> MotionModel:
    """The shipped :class:`~jcrowd.model.motion_model.MotionModel` (fitted from CMU subject 16's
    walks and turns; no data folder needed)."""
    return load_motion_model(default_model_path())[0]
