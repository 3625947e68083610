"""Key paths of a scenario's obstacle numbers, for layout optimisation (issue 22, item 3).

``jcrowd optimize --vary obstacles[1].center[0]=4.6:5.5`` names one number of an
``[[obstacles]]`` table by its TOML key path: :func:`parse_key_path` reads the path,
:func:`varied_parameter` checks it against the scenario and gives it bounds (default ±1 m for
coordinates, ×0.5 … ×1.5 for sizes and radii), and :func:`with_values` writes new values back
into the scenario, checked as a parsed scenario is. :mod:`jcrowd.rollouts.layout_opt` optimises
them.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from jcrowd.errors import JcrowdError, ScenarioError
from jcrowd.scenario.check import Problem
from jcrowd.scenario.geometry import Region
from jcrowd.scenario.layout import Layout
from jcrowd.scenario.schema import Scenario

__all__ = ["FIELDS", "Varied", "parse_key_path", "varied_parameter", "with_values"]

FIELDS = {"rect": ("center", "size"), "circle": ("center", "radius"), "polygon": ("points",)}
"""The numbers of each obstacle kind that can vary, in the order they are laid out."""


def parse_key_path(key: str) -> tuple[str | int, ...]:
    """``"obstacles[1].center[0]"`` → ``("obstacles", 1, "center", 0)``.

    Raises:
        JcrowdError: text that is not names joined by dots, each with optional ``[index]``es.
    """
    parts: list[str | int] = []
    for name in key.split("."):
        m = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)", name)
        if m is None:
            raise JcrowdError(
                f"key path {key!r}: expected names joined by dots, each with optional [index]es "
                f"(e.g. obstacles[1].center[0]), found {name!r}"
            )
        parts.append(m.group(1))
        parts += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return tuple(parts)


@dataclass(frozen=True)
class Varied:
    """One varied number: ``key`` (its TOML key path), the obstacle it belongs to, the field
    (``center``, ``size``, ``radius``, ``points``) and the index inside it, and its bounds."""

    key: str
    obstacle: int
    field: str
    index: tuple[int, ...]
    lower: float
    upper: float


def _default_bounds(field: str, value: float) -> tuple[float, float]:
    if field in ("size", "radius"):
        return 0.5 * value, 1.5 * value
    return value - 1.0, value + 1.0


def varied_parameter(
    scenario: Scenario, key: str, bounds: tuple[float, float] | None = None
) -> Varied:
    """The :class:`Varied` number at ``key`` with ``bounds`` (default: ±1 m for coordinates,
    ×0.5 … ×1.5 for sizes and radii).

    Raises:
        JcrowdError: a key that is not a number of an ``[[obstacles]]`` table of the scenario,
            or bounds that do not hold its current value.
    """
    path = parse_key_path(key)
    head = f"{scenario.source}: {key}"
    obstacles = scenario.layout.obstacles
    if len(path) < 3 or path[0] != "obstacles" or not isinstance(path[1], int):
        raise JcrowdError(
            f"{head}: expected a key of an [[obstacles]] table (e.g. obstacles[0].center[0]), "
            f"found {key!r}"
        )
    i, field, index = path[1], path[2], path[3:]
    if i >= len(obstacles):
        raise JcrowdError(f"{head}: expected an obstacle index below {len(obstacles)}, found {i}")
    region = obstacles[i]
    if field not in FIELDS[region.kind]:
        allowed = ", ".join(FIELDS[region.kind])
        raise JcrowdError(
            f"{head}: expected one of {allowed} (a {region.kind}'s numbers), found {field!r}"
        )
    value = np.asarray(getattr(region, str(field)), np.float64)
    if any(not isinstance(k, int) for k in index) or len(index) != value.ndim:
        raise JcrowdError(
            f"{head}: expected a number ({value.ndim} index(es) into {field}), found "
            f"{'an array' if len(index) < value.ndim else 'too many indexes'}"
        )
    ints = tuple(int(k) for k in index)
    if any(k >= n for k, n in zip(ints, value.shape, strict=True)):
        raise JcrowdError(f"{head}: expected indexes within {list(value.shape)}, found {ints}")
    current = float(value[ints])
    lo, hi = bounds if bounds is not None else _default_bounds(str(field), current)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise JcrowdError(f"{head}: expected bounds lo < hi, found [{lo}, {hi}]")
    if not lo <= current <= hi:
        raise JcrowdError(
            f"{head}: expected bounds holding its value {current:g}, found [{lo}, {hi}]"
        )
    return Varied(key, i, str(field), ints, float(lo), float(hi))


def with_values(
    scenario: Scenario, varied: Sequence[Varied], theta: Sequence[float] | np.ndarray
) -> Scenario:
    """The scenario with each varied number set to ``theta`` (checked as a parsed one is).

    Raises:
        ScenarioError: the new layout is invalid (an obstacle covering a goal, a degenerate
            polygon, …), naming the key.
    """
    obstacles = list(scenario.layout.obstacles)
    for v, value in zip(varied, theta, strict=True):
        region = obstacles[v.obstacle]
        array = np.array(getattr(region, v.field), np.float64)
        array[v.index] = float(value)
        kw: dict[str, Any] = {f: getattr(region, f) for f in FIELDS[region.kind]}
        kw[v.field] = float(array) if v.field == "radius" else array
        try:
            obstacles[v.obstacle] = Region(region.kind, **kw)
        except Problem as p:
            raise ScenarioError(f"{scenario.source}: {v.key}: {p.detail}") from None
    layout = Layout(tuple(obstacles), scenario.layout.walls, scenario.layout.walkable)
    try:
        return dataclasses.replace(scenario, layout=layout)
    except Problem as p:
        raise ScenarioError(f"{scenario.source}: {p.key}: {p.detail}") from None
