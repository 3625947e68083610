"""Tensor-model files (``.jcm`` of kind ``"tensor-model"``): the motion tensor and its key levels.

Stored with :mod:`jcrowd.io.store` (safetensors + JSON metadata, checksum, atomic write). What is
stored is a :class:`~jcrowd.model.tensor_model.TensorModel` as :func:`build_tensor_model
<jcrowd.model.tensor_model.build_tensor_model>` returns it; loading rebuilds it exactly.
"""

from __future__ import annotations

import os
from dataclasses import asdict

import numpy as np

from jcrowd.io.store import load_store, save_store, skeleton_from_json, skeleton_to_json
from jcrowd.model.posevec import PoseLayout
from jcrowd.model.samples import CONTROL_NAMES
from jcrowd.model.tensor_model import TensorLevel, TensorModel, TensorModelConfig
from jcrowd.tensor.algebra import Tucker

__all__ = ["KIND", "load_tensor_model", "save_tensor_model"]

KIND = "tensor-model"


def save_tensor_model(path: str | os.PathLike[str], model: TensorModel) -> None:
    """Write the model file (safetensors + JSON metadata), atomically."""
    tensors: dict[str, np.ndarray] = {
        "tensor": model.tensor,
        "layout/reference": model.layout.reference,
        "layout/scale": model.layout.scale,
        "samples/controls": model.controls,
        "samples/groups": model.groups,
        "samples/mirrored": model.mirrored.astype(np.uint8),
    }
    for i, lv in enumerate(model.levels):
        tensors[f"level{i}/core"] = lv.tucker.core
        for k, u in enumerate(lv.tucker.factors):
            tensors[f"level{i}/factor{k}"] = u
    meta = {
        "config": asdict(model.config),
        "skeleton": skeleton_to_json(model.skeleton),
        "order": list(model.order),
        "levels": [{"joints": list(lv.joints), "mse": lv.mse} for lv in model.levels],
        "sources": list(model.sources),
        "controls": list(CONTROL_NAMES),
    }
    save_store(path, tensors, meta, kind=KIND)


def load_tensor_model(path: str | os.PathLike[str]) -> TensorModel:
    """Read a file written by :func:`save_tensor_model` (checked: version, kind, checksum)."""
    t, meta = load_store(path, kind=KIND)
    cfg = dict(meta["config"])
    cfg.setdefault("level_fit", "freeze")  # a file that names no level fit holds the freeze fit
    for key in ("max_ranks", "min_ranks"):
        cfg[key] = tuple(cfg[key]) if cfg[key] is not None else None
    skel = skeleton_from_json(meta["skeleton"])
    layout = PoseLayout(skel.num_joints, t["layout/reference"], t["layout/scale"])
    levels = tuple(
        TensorLevel(
            Tucker(t[f"level{i}/core"], tuple(t[f"level{i}/factor{k}"] for k in range(3))),
            tuple(lv["joints"]),
            float(lv["mse"]),
        )
        for i, lv in enumerate(meta["levels"])
    )
    return TensorModel(
        TensorModelConfig(**cfg),
        skel,
        layout,
        tuple(meta["order"]),
        levels,
        t["samples/controls"],
        t["samples/groups"],
        tuple(meta["sources"]),
        t["samples/mirrored"].astype(bool),
        t["tensor"],
    )
