"""Body files (``.jcb``): a rigged body's meshes, bone weights and rig, stored with
:mod:`jcrowd.io.store` (safetensors + JSON metadata, checksum, atomic write) under the kind
``"body"``.

Tensors: ``rig/heads`` and ``rig/tails`` ``(B, 3)``; per resolution ``r`` (fine to coarse)
``mesh{r}/vertices``, ``mesh{r}/normals`` ``(V, 3)`` float32, ``mesh{r}/triangles`` ``(T, 3)``
int32, ``mesh{r}/bones`` ``(V, 4)`` uint8 and ``mesh{r}/weights`` ``(V, 4)`` float32. Metadata:
``bones`` (names, parents first), ``parents``, and the source, axes and licences.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from jcrowd.errors import SkinError, StoreError, where
from jcrowd.io.resources import body_path
from jcrowd.io.store import load_store, save_store
from jcrowd.model.motion_model import MotionModel
from jcrowd.motion.body import INFLUENCES, Body, BodyMesh, bind_body, rest_stature
from jcrowd.motion.clip import rest_forward

__all__ = ["KIND", "load_body", "save_body", "with_body_height"]

KIND = "body"
_FIELDS = ("vertices", "normals", "triangles", "bones", "weights")


def save_body(
    path: str | os.PathLike[str],
    meshes: Sequence[Mapping[str, np.ndarray]],
    heads: np.ndarray,
    tails: np.ndarray,
    meta: Mapping[str, Any],
) -> None:
    """Write a body: ``meshes`` as mappings of :data:`_FIELDS`, the rig's ``heads``/``tails``
    and ``meta`` (must hold ``bones`` and ``parents``)."""
    tensors: dict[str, np.ndarray] = {
        "rig/heads": np.asarray(heads, np.float32),
        "rig/tails": np.asarray(tails, np.float32),
    }
    for r, mesh in enumerate(meshes):
        for name in _FIELDS:
            tensors[f"mesh{r}/{name}"] = np.asarray(mesh[name])
    save_store(path, tensors, {**meta, "resolutions": len(meshes)}, kind=KIND)


def load_body(path: str | os.PathLike[str]) -> Body:
    """Read a body file (every check of :func:`~jcrowd.io.store.load_store`, then shapes, bone
    indices in range and weights summing to 1)."""
    t, meta = load_store(path, kind=KIND)
    p = where(path)
    bones = tuple(meta.get("bones", ()))
    parents = tuple(int(x) for x in meta.get("parents", ()))
    if not bones or len(parents) != len(bones):
        raise StoreError(f"{p}: expected bone names and one parent each, found {meta!r:.200}")
    meshes = []
    for r in range(int(meta.get("resolutions", 0))):
        m = {name: t[f"mesh{r}/{name}"] for name in _FIELDS}
        v = m["vertices"].shape[0]
        shapes_ok = (
            m["vertices"].shape == (v, 3)
            and m["normals"].shape == (v, 3)
            and m["triangles"].ndim == 2
            and m["triangles"].shape[1] == 3
            and m["bones"].shape == (v, INFLUENCES)
            and m["weights"].shape == (v, INFLUENCES)
        )
        if not shapes_ok:
            raise StoreError(
                f"{p}: mesh{r}: expected vertices/normals (V, 3), triangles (T, 3), bones and "
                f"weights (V, {INFLUENCES}); found "
                + ", ".join(f"{k} {m[k].shape}" for k in _FIELDS)
            )
        if m["triangles"].min() < 0 or m["triangles"].max() >= v:
            raise StoreError(f"{p}: mesh{r}: triangle indices outside 0..{v - 1}")
        if m["bones"].max() >= len(bones):
            raise StoreError(f"{p}: mesh{r}: bone indices outside 0..{len(bones) - 1}")
        if np.abs(m["weights"].sum(axis=1) - 1.0).max() > 1e-4:
            raise StoreError(f"{p}: mesh{r}: expected each vertex's weights to sum to 1")
        meshes.append(
            BodyMesh(
                m["vertices"],
                m["normals"],
                m["triangles"].astype(np.int32),
                m["bones"].astype(np.int32),
                m["weights"],
            )
        )
    if not meshes:
        raise StoreError(f"{p}: expected at least one mesh, found none")
    return Body(bones, parents, t["rig/heads"], t["rig/tails"], tuple(meshes))


def with_body_height(model: MotionModel, body: Body | None = None) -> MotionModel:
    """``model`` with :attr:`~jcrowd.model.motion_model.MotionModel.body_height` measured on
    ``body`` (default: the shipped body) bound to its skeleton
    (:func:`~jcrowd.motion.body.rest_stature`). A skeleton the body cannot be bound to (no
    legs or arms found by name) keeps the model's value: no body is drawn on it."""
    try:
        bound = bind_body(
            load_body(body_path()) if body is None else body,
            model.skeleton,
            rest_forward(model.skeleton),
        )
    except SkinError:
        return model
    return dataclasses.replace(model, body_height=rest_stature(bound))
