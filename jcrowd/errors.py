"""The project's one error family.

Every error a user can cause is a :class:`JcrowdError` (a ``ValueError``), so callers can catch
one type. Messages say what was expected, what was found, and where (``path:line`` for files,
a key path for scenarios).
"""

from __future__ import annotations

import os

__all__ = [
    "AlignError",
    "BVHError",
    "DataError",
    "JcrowdError",
    "KrigingError",
    "MotionError",
    "RenderError",
    "ScenarioError",
    "SkeletonError",
    "SkinError",
    "StoreError",
    "TensorError",
    "where",
]


class JcrowdError(ValueError):
    """Base class of every error jcrowd raises for bad input."""


class AlignError(JcrowdError):
    """Sequences or warps cannot be aligned as asked (empty, wrong shape, not finite, ...)."""


class BVHError(JcrowdError):
    """A BVH file could not be read or written."""


class SkeletonError(JcrowdError):
    """A skeleton's topology or offsets are invalid."""


class MotionError(JcrowdError):
    """A motion clip cannot be processed as asked (too short, no feet found, ...)."""


class DataError(JcrowdError):
    """A dataset folder or its labels file is invalid."""


class TensorError(JcrowdError):
    """A tensor, its ranks or its labels do not fit the decomposition asked for."""


class KrigingError(JcrowdError):
    """Samples, controls or a variogram cannot be kriged as asked (too few, not finite, ...)."""


class ScenarioError(JcrowdError):
    """A scenario file (TOML) is invalid: the message names the file and the key path."""


class RenderError(JcrowdError):
    """No rendering context could be made, or a frame cannot be drawn or written as asked."""


class SkinError(JcrowdError):
    """A body cannot be bound to a skeleton (parts of the body with no joint), or its weights
    are invalid."""


class StoreError(JcrowdError):
    """A model file could not be written, read or trusted."""


def where(path: str | os.PathLike[str], line: int | None = None) -> str:
    """Format a location as ``path:line`` (or just ``path``) for error messages."""
    return f"{os.fspath(path)}:{line}" if line is not None else os.fspath(path)
