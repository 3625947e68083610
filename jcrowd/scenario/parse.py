"""Reading scenario files: TOML → :class:`~jcrowd.scenario.schema.Scenario`, with key-path errors.

:func:`load_scenario` reads the file (the only IO besides checking that a model file exists);
:func:`parse_scenario` walks the tables — unknown and missing keys — and builds the dataclasses
of :mod:`jcrowd.scenario.schema`, which check their own values; every message is prefixed with the
file and the key path (``plaza.toml: groups[2].count: expected …, found …``). Both are re-exported
by :mod:`jcrowd.scenario.schema`.
"""

from __future__ import annotations

import os
import pathlib
import re
import tomllib
from collections.abc import Callable, Sequence
from typing import Any, NoReturn, TypeVar

from jcrowd.errors import ScenarioError, where
from jcrowd.scenario.check import Problem, show
from jcrowd.scenario.geometry import Region
from jcrowd.scenario.layout import Layout, Wall
from jcrowd.scenario.schema import (
    Camera,
    CameraKey,
    DynamicsSettings,
    Group,
    LodSettings,
    Path,
    Scenario,
    Source,
)

__all__ = ["load_scenario", "parse_scenario"]

_T = TypeVar("_T")
_TOP = (
    "model",
    "seed",
    "duration",
    "fps",
    "ground",
    "camera",
    "lod",
    "groups",
    "obstacles",
    "walls",
    "walkable",
    "dynamics",
    "sources",
)
_GROUP = ("name", "count", "spawn", "path", "goal", "speed", "height", "color")
_CAMERA = ("eye", "target", "keys", "fov", "width", "height", "near", "far")
_CAMERA_KEY = ("time", "eye", "target")
_SHAPES = {"rect": ("center", "size"), "circle": ("center", "radius"), "polygon": ("points",)}
_LOD = {  # TOML key → LodSettings field
    "thresholds": "thresholds_m",
    "hysteresis": "hysteresis_m",
    "capacities": "capacities",
    "blend_max_level": "blend_max_level",
    "importance": "screen",
    "min_pixels": "min_pixels",
    "plant_feet": "plant_feet",
}


class _Reader:
    """Walks the TOML document's tables; every message starts with the file and a key path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, detail: str) -> NoReturn:
        raise ScenarioError(f"{self.source}: {path}: {detail}")

    def build(self, at: str, make: Callable[..., _T], /, *args: Any, **kwargs: Any) -> _T:
        """``make(*args, **kwargs)``, its problems reported under the key path ``at``."""
        try:
            return make(*args, **kwargs)
        except Problem as p:
            self.fail(_join(at, p.key), p.detail)

    def table(
        self, value: Any, path: str, allowed: Sequence[str], required: Sequence[str] = ()
    ) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.fail(path, f"expected a table, found {show(value)}")
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            self.fail(_join(path, unknown[0]), f"unknown key; allowed keys: {', '.join(allowed)}")
        for key in required:
            if key not in value:
                self.fail(_join(path, key), "expected a value, found nothing (required key)")
        return value

    def region(self, value: Any, path: str, ground: bool = False) -> Region:
        t = self.table(value, path, ("shape", "center", "size", "radius", "points"))
        shape = t.get("shape", "rect" if ground else None)
        kinds = ("rect",) if ground else tuple(_SHAPES)
        if shape not in kinds:
            expected = '"rect"' if ground else '"rect", "circle" or "polygon"'
            found = "nothing" if shape is None else show(shape)
            self.fail(_join(path, "shape"), f"expected {expected}, found {found}")
        keys = _SHAPES[shape]
        self.table(t, path, ("shape", *keys), keys)
        return self.build(path, Region, shape, **{k: t[k] for k in keys})

    def group(self, value: Any, path: str) -> Group:
        t = self.table(value, path, _GROUP, ("count", "spawn"))
        kw: dict[str, Any] = {
            k: t[k] for k in ("name", "count", "speed", "height", "color") if k in t
        }
        kw.setdefault("name", path)
        kw["spawn"] = self.region(t["spawn"], f"{path}.spawn")
        if "path" in t:
            p = self.table(t["path"], f"{path}.path", ("waypoints", "loop"), ("waypoints",))
            kw["path"] = self.build(f"{path}.path", Path, p["waypoints"], p.get("loop", False))
        if "goal" in t:
            kw["goal"] = self.region(t["goal"], f"{path}.goal")
        return self.build(path, Group, **kw)

    def sources(self, doc: dict[str, Any]) -> tuple[Source, ...]:
        out = []
        for i, value in enumerate(self.tables(doc, "sources")):
            at = f"sources[{i}]"
            t = self.table(
                value, at, ("group", "rate", "start", "stop", "count", "region"), ("group", "rate")
            )
            kw: dict[str, Any] = {
                k: t[k] for k in ("group", "rate", "start", "stop", "count") if k in t
            }
            if "region" in t:
                kw["region"] = self.region(t["region"], f"{at}.region")
            out.append(self.build(at, Source, **kw))
        return tuple(out)

    def tables(self, doc: dict[str, Any], key: str) -> list[Any]:
        """The ``[[key]]`` tables of the document (none when absent)."""
        value = doc.get(key, [])
        if not isinstance(value, list):
            self.fail(key, f"expected [[{key}]] tables, found {show(value)}")
        return value

    def layout(self, doc: dict[str, Any]) -> Layout:
        obstacles = tuple(
            self.region(o, f"obstacles[{i}]") for i, o in enumerate(self.tables(doc, "obstacles"))
        )
        walls = []
        for i, w in enumerate(self.tables(doc, "walls")):
            path = f"walls[{i}]"
            t = self.table(w, path, ("points", "thickness"), ("points",))
            walls.append(self.build(path, Wall, t["points"], t.get("thickness", 0.2)))
        walkable = self.region(doc["walkable"], "walkable") if "walkable" in doc else None
        return Layout(obstacles, tuple(walls), walkable)

    def camera(self, value: Any) -> Camera:
        t = self.table(value, "camera", _CAMERA)
        if "keys" in t and ("eye" in t or "target" in t):
            self.fail("camera", "expected eye and target (fixed) or [[camera.keys]], found both")
        if "keys" in t:
            keys = t["keys"]
            if not isinstance(keys, list) or not keys:
                self.fail("camera.keys", f"expected [[camera.keys]] tables, found {show(keys)}")
            made = []
            for i, k in enumerate(keys):
                path = f"camera.keys[{i}]"
                k = self.table(k, path, _CAMERA_KEY, _CAMERA_KEY)
                made.append(self.build(path, CameraKey, k["time"], k["eye"], k["target"]))
        else:
            self.table(t, "camera", _CAMERA, ("eye", "target"))
            made = [self.build("camera", CameraKey, 0.0, t["eye"], t["target"])]
        names = {
            "fov": "fov_deg",
            "width": "width",
            "height": "height",
            "near": "near",
            "far": "far",
        }
        kw = {name: t[key] for key, name in names.items() if key in t}
        return self.build("camera", Camera, tuple(made), **kw)

    def model(self, value: Any, base_dir: pathlib.Path) -> str | None:
        if not isinstance(value, str) or not value:
            self.fail("model", f'expected "default" or a model file path, found {show(value)}')
        if value == "default":
            return None
        path = pathlib.Path(value).expanduser()
        path = (path if path.is_absolute() else base_dir / path).resolve()
        if not path.is_file():
            self.fail("model", f"expected an existing model file, found {show(value)} (no {path})")
        return str(path)

    def dynamics(self, value: Any, base_dir: pathlib.Path) -> DynamicsSettings:
        keys = ("avoid", "model", "radius", "far_every", "params")
        table = dict(self.table(value, "dynamics", keys))
        if "params" in table:
            table["params"], table["avoidance"], radius = self.params(table["params"], base_dir)
            if radius is not None and "radius" not in table:
                table["radius"] = radius  # the scenario's own radius wins over the file's
        return self.build("dynamics", DynamicsSettings, **table)

    def params(
        self, value: Any, base_dir: pathlib.Path
    ) -> tuple[str, tuple[tuple[str, float], ...], float | None]:
        """A parameters file (``jcrowd calibrate --out``): its ``[avoidance]`` numbers (the
        names are checked against the model's when the step is prepared) and its ``[body]``
        radius, if it has one."""
        at = "dynamics.params"
        if not isinstance(value, str) or not value:
            self.fail(at, f"expected a parameters file path, found {show(value)}")
        path = pathlib.Path(value).expanduser()
        path = (path if path.is_absolute() else base_dir / path).resolve()
        try:
            doc = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError:
            self.fail(at, f"expected an existing parameters file, found {show(value)} (no {path})")
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            self.fail(at, f"{path}: expected a TOML parameters file, found an invalid one ({e})")
        unknown = sorted(set(doc) - {"avoidance", "body", "population", "calibration"})
        table = doc.get("avoidance")
        body = doc.get("body", {})
        if unknown or not isinstance(table, dict) or not isinstance(body, dict):
            self.fail(
                at,
                f"{path}: expected an [avoidance] table of numbers (and optionally [body], "
                f"[population], [calibration]), found tables {sorted(doc)}",
            )
        if set(body) - {"radius"}:
            self.fail(at, f"{path}: body: expected only radius, found keys {sorted(body)}")
        numbers = {f"avoidance.{k}": v for k, v in table.items()}
        numbers |= {f"body.{k}": v for k, v in body.items()}
        for key, v in numbers.items():
            ok = isinstance(v, int | float) and not isinstance(v, bool) and 0 < v < float("inf")
            if not ok:
                self.fail(at, f"{path}: {key}: expected a positive number, found {show(v)}")
        radius = float(body["radius"]) if "radius" in body else None
        if radius is not None and not 0.1 <= radius <= 0.4:
            self.fail(
                at, f"{path}: body.radius: expected a radius in [0.1, 0.4] (m), found {radius}"
            )
        return str(path), tuple((str(k), float(v)) for k, v in table.items()), radius


def _join(path: str, key: str) -> str:
    if not path or not key:
        return path or key
    return path + key if key.startswith("[") else f"{path}.{key}"


def parse_scenario(
    text: str, source: str, base_dir: str | os.PathLike[str] | None = None
) -> Scenario:
    """Check and build a scenario from TOML ``text``.

    Args:
        text: the TOML document (layout in ``examples/README.md``).
        source: how messages name the file, e.g. ``"plaza.toml"``; kept as ``Scenario.source``.
        base_dir: folder a relative ``model`` path is resolved against (default: the current
            folder). The model file must exist.

    Raises:
        ScenarioError: ``source:line: invalid TOML …`` for syntax, else
            ``source: key.path: expected …, found …``.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        message = str(e)
        at = re.search(r"\s*\(at line (\d+), column (\d+)\)$", message)
        if at is not None:
            line, detail = int(at.group(1)), f"{message[: at.start()]} (column {at.group(2)})"
        else:  # "(at end of document)"
            line, detail = text.count("\n") + 1, message
        raise ScenarioError(f"{where(source, line)}: invalid TOML: {detail}") from None
    r = _Reader(source)
    r.table(doc, "", _TOP, ("duration", "ground", "camera", "groups"))
    groups = doc["groups"]
    if not isinstance(groups, list) or not groups:
        r.fail("groups", f"expected at least one [[groups]] table, found {show(groups)}")
    lod = r.table(doc.get("lod", {}), "lod", tuple(_LOD))
    base = pathlib.Path(base_dir) if base_dir is not None else pathlib.Path.cwd()
    return r.build(
        "",
        Scenario,
        source=source,
        model=r.model(doc.get("model", "default"), base),
        seed=doc.get("seed", 0),
        duration_s=doc["duration"],
        fps=doc.get("fps", 30.0),
        ground=r.region(doc["ground"], "ground", ground=True),
        groups=tuple(r.group(g, f"groups[{i}]") for i, g in enumerate(groups)),
        camera=r.camera(doc["camera"]),
        lod=r.build("lod", LodSettings, **{_LOD[k]: v for k, v in lod.items()}),
        layout=r.layout(doc),
        dynamics=r.dynamics(doc.get("dynamics", {}), base),
        sources=r.sources(doc),
    )


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and parse a scenario file; a relative ``model`` path is taken from the file's folder.

    The file is named in messages as ``path`` was given.
    """
    source = os.fspath(path)
    file = pathlib.Path(source)
    try:
        raw = file.read_bytes()
    except FileNotFoundError:
        raise ScenarioError(f"{source}: expected a scenario file, found no such file") from None
    except IsADirectoryError:
        raise ScenarioError(f"{source}: expected a scenario file, found a folder") from None
    except OSError as e:
        raise ScenarioError(f"{source}: cannot be read ({e.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        found = f"byte {raw[e.start]:#04x}"
        raise ScenarioError(f"{where(source, line)}: expected UTF-8 text, found {found}") from None
    return parse_scenario(text, source, base_dir=file.resolve().parent)
