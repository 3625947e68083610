"""Field checks shared by the scenario dataclasses: values, their TOML spelling in messages.

Each check raises :class:`Problem` (a :class:`~jcrowd.errors.ScenarioError`) whose key is
relative to the object being built; :mod:`jcrowd.scenario.parse` prefixes the file and the path.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np

from jcrowd.errors import ScenarioError

__all__ = ["Problem", "Raw", "is_int", "points", "real", "reals", "require", "show", "value_range"]


class Problem(ScenarioError):
    """A failed check inside a dataclass; ``key`` is relative to the object being built."""

    def __init__(self, key: str, detail: str) -> None:
        super().__init__(f"{key}: {detail}" if key else detail)
        self.key, self.detail = key, detail


class Raw(str):
    """Text shown as is in a message (``show`` quotes a plain string)."""


def show(value: Any) -> str:
    """A value as TOML would spell it, shortened, for error messages."""
    if isinstance(value, Raw):
        return str(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, numbers.Real):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, Mapping):
        return "a table {" + ", ".join(map(str, value)) + "}"
    if isinstance(value, list | tuple):
        items = [show(v) for v in value[:6]] + (["…"] if len(value) > 6 else [])
        return "[" + ", ".join(items) + "]"
    return str(value)


def require(ok: Any, key: str, expected: str, found: Any) -> None:
    if not ok:
        raise Problem(key, f"expected {expected}, found {show(found)}")


def real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


def is_int(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def reals(value: Any, key: str, expected: str, n: int | None = None) -> np.ndarray:
    """A 1-D float64 array of finite numbers (``n`` of them when given); no bools or strings."""
    if isinstance(value, np.ndarray):
        ok = value.ndim == 1 and value.dtype.kind in "iuf" and bool(np.all(np.isfinite(value)))
    else:
        ok = isinstance(value, list | tuple) and all(real(v) for v in value)
    require(ok and len(value) > 0 and (n is None or len(value) == n), key, expected, value)
    return np.array(value, np.float64)


def points(value: Any, key: str) -> np.ndarray:
    """A ``(P, 2)`` float64 array of ``[x, z]`` points, P ≥ 1."""
    if isinstance(value, np.ndarray):
        ok = value.ndim == 2 and value.shape[1] == 2 and value.dtype.kind in "iuf"
        ok = ok and len(value) > 0 and bool(np.all(np.isfinite(value)))
    else:
        ok = isinstance(value, list | tuple) and len(value) > 0
        ok = ok and all(isinstance(p, list | tuple) and len(p) == 2 for p in value)
        ok = ok and all(real(v) for p in value for v in p)
    require(ok, key, "a list of [x, z] points (m)", value)
    return np.array(value, np.float64)


def value_range(
    value: Any, key: str, bounds: tuple[float, float], unit: str
) -> tuple[float, float]:
    expected = f"[lo, hi] {unit} with {bounds[0]} ≤ lo ≤ hi ≤ {bounds[1]}"
    lo, hi = (value, value) if real(value) else reals(value, key, expected, 2)
    require(bounds[0] <= lo <= hi <= bounds[1], key, expected, value)
    return float(lo), float(hi)
