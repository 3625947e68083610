"""``jcrowd render SCENARIO.toml|RUN.npz --out out.mp4|out.gif|DIR``: headless crowd rendering.

From a scenario the crowd is stepped and drawn frame by frame (step and draw timed apart); from
a recording of ``jcrowd run --record visible|all`` the recorded joints are drawn (bodies are
bound to the model the recording names, or ``--model``). Agents are skinned bodies
(``--style body``, default; :mod:`jcrowd.render.bodies`) or capsules round the bones
(``--style capsules``, the debug view), in clothes of their own (``--color-by tint``, default),
or coloured by level (like paper 000 Fig. 6) or by group. The
output is an MP4 or GIF clip, or a folder of numbered PNG frames. ``--json`` prints ``frames``,
``out``, ``ms_per_frame_median`` (drawing and read-back), ``ms_per_step_median`` (scenarios).
``--eye X,Y,Z --target X,Y,Z`` sees a scenario from a fixed camera of one's own (a close-up,
say); its levels of detail then follow that camera.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_parser", "fixed_camera", "parse_point", "parse_size", "render_scenario", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "render", help="render a scenario or a recorded run", description=__doc__
    )
    p.add_argument("source", help="a scenario (.toml) or a recording (.npz) of jcrowd run")
    p.add_argument("--out", required=True, help="out.mp4, out.gif or a folder for PNG frames")
    p.add_argument("--size", help="WIDTHxHEIGHT (default: the scenario camera's)")
    p.add_argument("--frames", type=int, help="frames to render (default: all)")
    p.add_argument(
        "--style",
        choices=("body", "capsules"),
        default="body",
        help="skinned bodies (default) or capsules round the bones (a debug view)",
    )
    p.add_argument(
        "--color-by",
        choices=("level", "group", "tint"),
        default="tint",
        help="bodies' clothes (or capsules) by level of detail, by group, or varied per agent",
    )
    p.add_argument("--model", help="model file for a scenario (default: the scenario's)")
    p.add_argument(
        "--eye", help="X,Y,Z: a scenario seen from this fixed camera instead (m; with --target)"
    )
    p.add_argument("--target", help="X,Y,Z: where the --eye camera looks (m)")
    return p


def parse_point(text: str, option: str) -> tuple[float, float, float]:
    """``"3,1.7,-4"`` → ``(3.0, 1.7, -4.0)``."""
    from jcrowd.errors import RenderError

    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise RenderError(
            f"{option}: expected X,Y,Z in metres like 3,1.7,-4, found {text!r}"
        ) from None
    return x, y, z


def fixed_camera(scenario: Any, eye: str | None, target: str | None) -> Any:
    """The scenario with its camera replaced by a fixed one at ``eye`` looking at ``target``
    (both or neither; the LOD then follows this camera too)."""
    from dataclasses import replace

    from jcrowd.errors import RenderError
    from jcrowd.scenario.camera import CameraKey

    if eye is None and target is None:
        return scenario
    if eye is None or target is None:
        raise RenderError("--eye and --target: expected both (a fixed camera), found one")
    key = CameraKey(
        0.0, np.array(parse_point(eye, "--eye")), np.array(parse_point(target, "--target"))
    )
    return replace(scenario, camera=replace(scenario.camera, keys=(key,)))


def parse_size(text: str | None, default: tuple[int, int]) -> tuple[int, int]:
    """``"1280x720"`` → ``(1280, 720)``; positive even numbers."""
    from jcrowd.errors import RenderError

    if text is None:
        return default
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise RenderError(f"--size: expected WIDTHxHEIGHT like 1280x720, found {text!r}") from None
    if w <= 0 or h <= 0 or w % 2 or h % 2:
        raise RenderError(f"--size: expected positive even numbers, found {text!r}")
    return w, h


class _Sink:
    """Frames to a clip (.mp4/.gif) or to numbered PNGs in a folder."""

    def __init__(self, out: str, fps: float):
        from jcrowd.render import VIDEO_SUFFIXES, VideoWriter

        self.path = Path(out)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.video = VideoWriter(out, fps) if self.path.suffix.lower() in VIDEO_SUFFIXES else None
        if self.video is None:
            self.path.mkdir(parents=True, exist_ok=True)
        self.count = 0

    def add(self, image: np.ndarray) -> None:
        from jcrowd.render import write_png

        if self.video is not None:
            self.video.append(image)
        else:
            write_png(self.path / f"frame_{self.count:05d}.png", image)
        self.count += 1

    def close(self, ok: bool) -> None:
        if self.video is not None:
            self.video.close() if ok else self.video.abort()


def _view(scenario: Any, t: float) -> Any:
    from jcrowd.render import View
    from jcrowd.scenario.camera import camera_at

    cam = scenario.camera
    eye, target = camera_at(cam, t)
    return View(tuple(eye), tuple(target), fov_deg=cam.fov_deg, near=cam.near, far=cam.far)


def _colors(
    color_by: str, level: int, ids: np.ndarray, group_colors: np.ndarray, tints: Any = None
) -> np.ndarray:
    """Colours of the agents ``ids`` (slots past the end take the last agent's): by level, by
    group, or their tint (``(n, 3, 3)`` skin, top, bottom; capsules take the top)."""
    from jcrowd.render import LEVEL_COLORS

    if color_by == "group":
        return group_colors[np.minimum(ids, len(group_colors) - 1)]
    if color_by == "tint" and tints is not None:
        return tints[np.minimum(ids, len(tints) - 1)]
    return np.broadcast_to(np.asarray(LEVEL_COLORS[level], np.float32), (len(ids), 3))


def _for_capsules(colors: np.ndarray) -> np.ndarray:
    """A capsule takes one colour per agent: the top of a ``(n, 3, 3)`` tint."""
    return colors[:, 1] if colors.ndim == 3 else colors


def body_levels(model: Any, decoders: Any = None) -> tuple[Any, ...]:
    """The shipped body bound to ``model``'s skeleton, skinned to each level's joints."""
    from jcrowd.crowd.bodies import skinned_levels
    from jcrowd.io.body_file import load_body
    from jcrowd.io.resources import body_path
    from jcrowd.motion.body import bind_body
    from jcrowd.motion.clip import rest_forward

    bound = bind_body(load_body(body_path()), model.skeleton, rest_forward(model.skeleton))
    return skinned_levels(model, bound, decoders=decoders)


DOT_PARENTS = (-1, 0)
"""A dot agent (below ``lod.min_pixels`` on screen) is drawn as one bone, ground to head."""


def _dot_sticks(xz: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """``(N, 2, 3)``: each agent's root on the ground and the top of its head."""
    ground = np.stack([xz[:, 0], np.zeros(len(xz), np.float32), xz[:, 1]], axis=1)
    head = ground.copy()
    head[:, 1] = heights
    return np.stack([ground, head], axis=1)


def _level_instances(
    host: Any,
    color_by: str,
    group_colors: np.ndarray,
    tints: Any,
    heights: np.ndarray,
    capsules: bool,
) -> list[Any]:
    """One :class:`~jcrowd.render.LevelInstances` per level from a frame's host
    ``(slots, valid, points)``: each agent's colours and height."""
    from jcrowd.render import LevelInstances

    n = len(heights)
    levels = []
    for lv, (slots, valid, pts) in enumerate(zip(*host, strict=True)):
        cols = _colors(color_by, lv, slots, group_colors, tints)
        if capsules:
            cols = _for_capsules(cols)
        levels.append(LevelInstances(pts, valid, cols, heights[np.minimum(slots, n - 1)]))
    return levels


def _dot_instances(
    xz: np.ndarray,
    dots: np.ndarray,
    color_by: str,
    group_colors: np.ndarray,
    tints: Any,
    heights: np.ndarray,
    level: int,
) -> Any:
    """The agents drawn as dots (one stick each, ground to head), in their colours."""
    from jcrowd.render import LevelInstances

    colors = _colors(color_by, level, np.arange(len(heights)), group_colors, tints)
    return LevelInstances(_dot_sticks(xz, heights), dots, _for_capsules(colors))


def _drawn(state: Any, view: Any, frame: Any) -> dict[str, Any]:
    """What a rendered frame needs from a step: the dots' positions at the frame's start and
    the bodies the frame draws."""
    return {
        "xz": state.position,
        "dots": frame.dots,
        "slots": frame.slots,
        "valid": frame.valid,
        "points": frame.points,
    }


def render_scenario(
    scenario: Any,
    model: Any,
    out: str,
    size: tuple[int, int],
    frames: int | None,
    color_by: str,
    still: str | None = None,
    style: str = "body",
) -> dict[str, Any]:
    """Step and draw ``scenario``; write the clip (and optionally one PNG still)."""
    from jcrowd.cli.runloop import RunLoop, scenario_obstacles
    from jcrowd.crowd.devices import in_agent_order, shard_state
    from jcrowd.crowd.simulate import prepare
    from jcrowd.crowd.synthesis import point_parents
    from jcrowd.render import CrowdRenderer, write_png
    from jcrowd.render.bodies import tint_palette

    sim, state = prepare(scenario, model)
    bodies = body_levels(model, sim.crowd.decoders) if style == "body" else None
    loop = RunLoop(sim, shard_state(state), _drawn)  # one block of agents per device
    n_frames = sim.steps if frames is None else frames
    group_colors = np.asarray(sim.spawn.color, np.float32)
    n = sim.num_agents
    heights = np.asarray(sim.spawn.height / model.body_height, np.float32)  # skeleton scales
    tints = tint_palette(n)
    # Slots per level as the step returns them (split over K devices a level holds K shares of
    # its capacity, rounded up: jcrowd.crowd.devices.per_device_config).
    caps = tuple(int(s.shape[0]) for s in loop.shapes["slots"])
    draw_ms = []
    sink = _Sink(out, scenario.fps)
    ok = False
    middle = None

    try:
        with CrowdRenderer(
            [point_parents(model)] * len(caps) + [DOT_PARENTS],
            *size,
            capacity=(*caps, n),
            obstacles=scenario_obstacles(scenario),
            bodies=None if bodies is None else [*bodies, None],
            sky=bodies is not None,
        ) as renderer:
            for i, rec in loop.frames(n_frames, f"rendering {n_frames} frames"):
                t = time.perf_counter()
                host = (rec["slots"], rec["valid"], rec["points"])
                xz = in_agent_order(rec["xz"], loop.state)
                dots = in_agent_order(rec["dots"], loop.state)
                levels = _level_instances(
                    host, color_by, group_colors, tints, heights, bodies is None
                )
                dot = _dot_instances(xz, dots, color_by, group_colors, tints, heights, len(caps))
                image = renderer.render(_view(scenario, i * sim.dt), [*levels, dot])
                draw_ms.append(1e3 * (time.perf_counter() - t))
                sink.add(image)
                if i == n_frames // 2:
                    middle = image
            renderer_name = renderer.renderer_name
        ok = True
    finally:
        sink.close(ok)
    if still is not None and middle is not None:
        write_png(still, middle)
    return {
        "frames": n_frames,
        "agents": sim.num_agents,
        "out": str(out),
        "size": list(size),
        "ms_per_frame_median": float(np.median(draw_ms)),
        "ms_per_step_median": 1e3 * float(np.median(loop.step_seconds)),
        "compile_s": loop.compile_s,
        "renderer": renderer_name,
    }


def _recording_bodies(path: str, rec: Any, nlev: int, model_path: str | None) -> tuple[Any, float]:
    """The bodies a recording is drawn with, bound to the model it names (or ``model_path``),
    and that model's ``body_height``."""
    from jcrowd.errors import RenderError
    from jcrowd.io.model_file import load_motion_model

    name = model_path or (str(rec["model"]) if "model" in rec else "")
    if not name:
        raise RenderError(f"{path}: names no model to bind bodies to; pass --model")
    model, _ = load_motion_model(name)
    if len(model.levels) != nlev:
        raise RenderError(
            f"{path}: recorded {nlev} levels, the model {name} has {len(model.levels)}"
        )
    return body_levels(model), model.body_height


def render_recording(
    path: str,
    out: str,
    size: tuple[int, int] | None,
    frames: int | None,
    color_by: str,
    style: str = "body",
    model_path: str | None = None,
) -> dict[str, Any]:
    """Draw the joints recorded by ``jcrowd run --record visible|all``: as bodies (bound to the
    model the recording names, or ``model_path``) or capsules."""
    from jcrowd.errors import RenderError
    from jcrowd.render import CrowdRenderer, View
    from jcrowd.render.bodies import tint_palette

    rec = np.load(path)
    nlev = int(rec["levels"]) if "levels" in rec else 0
    if "points_0" not in rec:
        raise RenderError(
            f"{path}: expected joints recorded with `jcrowd run --record visible` (or all), "
            f"found only {sorted(rec.files)}"
        )
    parents = tuple(int(p) for p in rec["parents"])
    n_frames = rec["points_0"].shape[0] if frames is None else min(frames, rec["points_0"].shape[0])
    caps = [rec[f"points_{lv}"].shape[1] for lv in range(nlev)]
    w, h = size or (1280, 720)
    bodies, body_height = (
        _recording_bodies(path, rec, nlev, model_path) if style == "body" else (None, 1.0)
    )
    heights = np.asarray(rec["height"] / body_height, np.float32)  # statures → skeleton scales
    tints = tint_palette(len(heights))
    group_colors = np.asarray(rec["color"], np.float32)
    fov, near, far = (float(v) for v in rec["lens"])
    dots = "dots" in rec  # a recording without detail culling has none
    n = len(heights)
    draw_ms = []
    sink = _Sink(out, float(rec["fps"]))
    ok = False
    try:
        with CrowdRenderer(
            [parents] * nlev + ([DOT_PARENTS] if dots else []),
            w,
            h,
            capacity=caps + ([n] if dots else []),
            obstacles=rec["obstacles"] if "obstacles" in rec else None,  # scenarios with a layout
            bodies=None if bodies is None else [*bodies] + ([None] if dots else []),
            sky=bodies is not None,
        ) as renderer:
            for i in range(n_frames):
                t = time.perf_counter()
                host = tuple(
                    [rec[f"{k}_{lv}"][i] for lv in range(nlev)]
                    for k in ("slots", "valid", "points")
                )
                levels = _level_instances(
                    host, color_by, group_colors, tints, heights, bodies is None
                )
                if dots:
                    xz, shown = rec["position"][i], rec["dots"][i]
                    levels.append(
                        _dot_instances(xz, shown, color_by, group_colors, tints, heights, nlev)
                    )
                view = View(
                    tuple(rec["eye"][i]), tuple(rec["target"][i]), fov_deg=fov, near=near, far=far
                )
                sink.add(renderer.render(view, levels))
                draw_ms.append(1e3 * (time.perf_counter() - t))
            name = renderer.renderer_name
        ok = True
    finally:
        sink.close(ok)
    return {
        "frames": n_frames,
        "out": str(out),
        "size": [w, h],
        "ms_per_frame_median": float(np.median(draw_ms)),
        "renderer": name,
    }


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit
    from jcrowd.cli.runloop import load_model
    from jcrowd.scenario.parse import load_scenario

    if Path(args.source).suffix.lower() == ".npz":
        if args.eye or args.target:
            from jcrowd.errors import RenderError

            raise RenderError("--eye/--target: a recording keeps its camera; give a scenario")
        size = parse_size(args.size, (1280, 720))
        result = render_recording(
            args.source, args.out, size, args.frames, args.color_by, args.style, args.model
        )
    else:
        scenario = fixed_camera(load_scenario(args.source), args.eye, args.target)
        model, _ = load_model(scenario, args.model)
        size = parse_size(args.size, (scenario.camera.width, scenario.camera.height))
        result = render_scenario(
            scenario, model, args.out, size, args.frames, args.color_by, style=args.style
        )
    emit(result, args.json, _print)
    return result


def _print(result: dict[str, Any]) -> None:
    sys.stdout.write(
        f"{result['frames']} frames → {result['out']} ({result['size'][0]}×{result['size'][1]}, "
        f"{result['ms_per_frame_median']:.0f} ms per frame drawn, {result['renderer']})\n"
    )
