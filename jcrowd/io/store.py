"""Model files: safetensors tensors plus one JSON metadata document, written atomically.

Layout: a standard `safetensors <https://huggingface.co/docs/safetensors>`_ file (so any
safetensors reader can list and load the arrays; no pickle anywhere). Its header's
``__metadata__`` holds one key, ``"jcrowd"``, whose value is a JSON document::

    {"format": "jcrowd-model", "format_version": 1, "kind": "...", "jcrowd_version": "...",
     "sha256": "<hex digest of the tensors>", "meta": {...caller's metadata...}}

The digest covers every tensor's name, dtype, shape and bytes in name order, so a flipped bit in
the data is caught even though safetensors itself would load it. Loading checks, in order: the
file can be read and parsed (truncation, garbage), it is a jcrowd model file, its format version
is one this jcrowd reads, its kind is the expected one, and the digest matches; each failure is a
:class:`~jcrowd.errors.StoreError` naming the file. Skeletons are stored in the metadata with
:func:`skeleton_to_json` (float32 offsets survive JSON exactly: every float32 is a double, and
JSON numbers round-trip doubles).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from jcrowd.errors import StoreError, where
from jcrowd.io.atomic import write_atomic
from jcrowd.motion.skeleton import Skeleton

__all__ = [
    "FORMAT_VERSION",
    "load_store",
    "save_store",
    "skeleton_from_json",
    "skeleton_to_json",
]

FORMAT_VERSION = 1
"""The model-file format this jcrowd writes; it reads this version and older ones."""

_FORMAT = "jcrowd-model"


def _digest(tensors: Mapping[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(tensors):
        a = np.ascontiguousarray(tensors[name])
        h.update(f"{name}|{a.dtype.str}|{a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_store(
    path: str | os.PathLike[str],
    tensors: Mapping[str, np.ndarray],
    meta: Mapping[str, Any],
    *,
    kind: str,
) -> None:
    """Write ``tensors`` and JSON-serialisable ``meta`` to ``path`` atomically."""
    from safetensors.numpy import save

    from jcrowd.version import __version__

    arrays = {k: np.ascontiguousarray(v) for k, v in tensors.items()}
    for name, a in arrays.items():
        if a.dtype == object:
            raise StoreError(f"{where(path)}: tensor {name!r} has dtype object; expected numbers")
    doc = {
        "format": _FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "jcrowd_version": __version__,
        "sha256": _digest(arrays),
        "meta": meta,
    }
    try:
        header = json.dumps(doc, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise StoreError(f"{where(path)}: metadata is not JSON-serialisable: {e}") from e
    write_atomic(path, save(arrays, metadata={"jcrowd": header}), error=StoreError)


def load_store(
    path: str | os.PathLike[str], *, kind: str | None = None
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read a model file; returns ``(tensors, meta)`` after every check in the module docstring."""
    from safetensors import SafetensorError
    from safetensors.numpy import load

    p = where(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise StoreError(f"{p}: cannot read the model file: {e.strerror or e}") from e
    if len(data) < 8:
        raise StoreError(f"{p}: expected a jcrowd model file, found {len(data)} bytes (truncated?)")
    header_len = int.from_bytes(data[:8], "little")
    if header_len <= 0 or 8 + header_len > len(data):
        raise StoreError(
            f"{p}: expected a safetensors header of {header_len} bytes, the file has "
            f"{len(data) - 8} after the length (truncated or not a model file)"
        )
    try:
        header = json.loads(data[8 : 8 + header_len])
        tensors = load(data)
    except (ValueError, SafetensorError) as e:
        raise StoreError(f"{p}: not a readable model file (truncated or corrupted): {e}") from e
    raw = header.get("__metadata__", {}).get("jcrowd") if isinstance(header, dict) else None
    if raw is None:
        raise StoreError(f"{p}: expected a jcrowd model file, found a file without jcrowd metadata")
    try:
        doc = json.loads(raw)
    except ValueError as e:
        raise StoreError(f"{p}: the jcrowd metadata is not valid JSON (corrupted): {e}") from e
    if not isinstance(doc, dict) or doc.get("format") != _FORMAT:
        raise StoreError(f"{p}: expected format {_FORMAT!r}, found {doc.get('format')!r}")
    version = doc.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION or version < 1:
        raise StoreError(
            f"{p}: format version {version!r}; this jcrowd reads versions 1..{FORMAT_VERSION} "
            f"(written by jcrowd {doc.get('jcrowd_version')!r}: upgrade jcrowd to read it)"
        )
    if kind is not None and doc.get("kind") != kind:
        raise StoreError(f"{p}: expected a {kind!r} file, found {doc.get('kind')!r}")
    if _digest(tensors) != doc.get("sha256"):
        raise StoreError(f"{p}: checksum mismatch: the tensor data was changed or corrupted")
    return tensors, doc.get("meta", {})


def skeleton_to_json(skeleton: Skeleton) -> dict[str, Any]:
    """A skeleton as plain JSON data (names, parents, offsets, End Sites)."""
    return {
        "names": list(skeleton.names),
        "parents": list(skeleton.parents),
        "offsets": np.asarray(skeleton.offsets, np.float32).astype(float).tolist(),
        "end_parents": list(skeleton.end_parents),
        "end_offsets": np.asarray(skeleton.end_offsets_or_empty(), np.float32)
        .astype(float)
        .tolist(),
    }


def skeleton_from_json(doc: Mapping[str, Any]) -> Skeleton:
    """Inverse of :func:`skeleton_to_json` (float32 offsets, bit-identical)."""
    try:
        return Skeleton(
            tuple(doc["names"]),
            tuple(int(p) for p in doc["parents"]),
            np.asarray(doc["offsets"], np.float32).reshape(-1, 3),
            tuple(int(p) for p in doc["end_parents"]),
            np.asarray(doc["end_offsets"], np.float32).reshape(-1, 3),
        )
    except (KeyError, TypeError, ValueError) as e:
        raise StoreError(f"skeleton metadata: expected names/parents/offsets/End Sites, {e}") from e
