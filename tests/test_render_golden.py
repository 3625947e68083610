"""Golden-image tests of the renderer: four tiny scenes compared with PNGs under tests/golden/.

The scenes are defined here and only here; ``python scripts/make_golden.py`` imports them to
(re)generate the PNGs. The tests never write a golden file: a mismatch fails and leaves the
rendered image in pytest's tmp folder for inspection.

Tolerance (DESIGN §6): a pixel fails when any channel differs by more than 4/255; an image fails
when more than 1 % of its pixels fail. Rasterisers differ in sub-pixel coverage on edges (MSAA
sample positions, LLVM versions of llvmpipe), which moves a handful of edge pixels by more than
a few levels; interior shading differs by at most a rounding step. 1 % of a 160×120 image is
192 pixels, far fewer than one misplaced bone would change (a 1.75 m character here covers
≈ 1,000 pixels), so the test still catches a moved, missing or recoloured agent.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import moderngl
import numpy as np
import pytest

from jcrowd.io.body_file import load_body
from jcrowd.io.resources import body_path
from jcrowd.motion import (
    character_height,
    forward_kinematics,
    procedural_walk,
    rest_forward,
    rest_positions,
    walker_skeleton,
)
from jcrowd.motion.body import bind_body
from jcrowd.motion.skeleton import end_site_positions
from jcrowd.motion.skinning import SkinnedLevel, skeleton_level
from jcrowd.render import (
    LEVEL_COLORS,
    CrowdRenderer,
    LevelInstances,
    View,
    write_png,
)

GOLDEN = Path(__file__).resolve().parent / "golden"
WIDTH, HEIGHT = 160, 120
PIXEL_TOL = 4  # /255, per channel (see the module docstring)
IMAGE_TOL = 0.01  # share of failing pixels

# Coarser LOD skeletons made from the walker's by keeping a subset of joints (each kept joint's
# parent is its nearest kept ancestor), as the joint levels of paper 003 do.
LEVEL1_KEEP = (0, 1, 2, 3, 5, 6, 7, 9, 10, 11, 13, 14, 16, 17)  # no toes, head, hands
LEVEL2_KEEP = (0, 2, 3, 6, 7, 10, 12, 14, 17)  # hips, knees, ankles, chest, head, elbows


@dataclass(frozen=True)
class Scene:
    """A tiny scene: per-level skeletons and capacities, the camera, and the instances."""

    levels: tuple[tuple[int, ...], ...]
    capacity: tuple[int, ...]
    view: View
    instances: tuple[LevelInstances, ...]
    bodies: tuple[SkinnedLevel | None, ...] | None = None
    sky: bool = False


def reduce_skeleton(parents: tuple[int, ...], keep: tuple[int, ...]) -> tuple[int, ...]:
    """Parents of the skeleton made of the joints ``keep`` (in order) of ``parents``."""
    new_index = {j: i for i, j in enumerate(keep)}
    out = []
    for j in keep:
        p = parents[j]
        while p >= 0 and p not in new_index:
            p = parents[p]
        out.append(new_index[p] if p >= 0 else -1)
    return tuple(out)


def tpose(height: float = 1.75) -> np.ndarray:
    """The walker skeleton's joints ``(19, 3)`` in a T-pose: rest pose, arms out sideways, feet
    on the ground. (The walker's rest pose has the arms hanging; here each arm chain is laid
    along ±X with its rest bone lengths.)"""
    skeleton = walker_skeleton(height)
    pos, _ = rest_positions(skeleton)
    offsets = np.asarray(skeleton.offsets, np.float64)
    for chain, sign in (((13, 14, 15), 1.0), ((16, 17, 18), -1.0)):
        for parent, joint in itertools.pairwise(chain):
            pos[joint] = pos[parent] + (sign * np.linalg.norm(offsets[joint]), 0.0, 0.0)
    pos[:, 1] -= pos[:, 1].min()
    return pos


def walk_poses() -> np.ndarray:
    """Joint positions ``(F, 19, 3)`` of one walker gait cycle, root above the origin."""
    motion, _ = procedural_walk(cycles=1, fps=30.0, seed=3)
    _, pos = forward_kinematics(motion.skeleton, motion.rotations, motion.root_positions)
    pos = np.asarray(pos, np.float64)
    return pos - pos[:, :1] * np.array([1.0, 0.0, 1.0])


def place(pose: np.ndarray, x: float, z: float, yaw: float = 0.0) -> np.ndarray:
    """``pose`` turned by ``yaw`` about +Y (from +Z towards +X) and moved to ``(x, 0, z)``."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return pose @ rot.T + np.array([x, 0.0, z])


def _instances(poses: list[np.ndarray], level: int, capacity: int) -> LevelInstances:
    """Fill ``capacity`` slots with ``poses``; padding slots hold NaN (never drawn)."""
    joints = np.full((capacity, poses[0].shape[0], 3), np.nan, np.float32)
    joints[: len(poses)] = np.stack(poses)
    valid = np.arange(capacity) < len(poses)
    colors = np.tile(LEVEL_COLORS[level], (capacity, 1))
    return LevelInstances(joints, valid, colors)


def scene_tpose() -> Scene:
    """One level-0 agent in a T-pose facing the camera, slightly from above."""
    parents = walker_skeleton().parents
    view = View(eye=(0.0, 1.5, 3.6), target=(0.0, 0.9, 0.0), fov_deg=50.0)
    return Scene((parents,), (1,), view, (_instances([tpose()], 0, 1),))


def scene_three_levels() -> Scene:
    """Five walking agents at three levels (2 + 2 + 1), coarser levels further away."""
    parents = walker_skeleton().parents
    poses = walk_poses()
    p1, p2 = reduce_skeleton(parents, LEVEL1_KEEP), reduce_skeleton(parents, LEVEL2_KEEP)
    # Spread so no agent hides another: seen from the eye, near agents sit at ±0.27 rad, mid
    # ones at about ±0.45 rad and the far one in the middle.
    near = [place(poses[0], -1.2, 1.5, 0.3), place(poses[12], 1.2, 1.5, -0.5)]
    mid = [
        place(poses[20], -4.5, -4.0, 1.2)[list(LEVEL1_KEEP)],
        place(poses[6], 4.3, -4.0, 2.5)[list(LEVEL1_KEEP)],
    ]
    far = [place(poses[30], 0.2, -5.0, -1.5708)[list(LEVEL2_KEEP)]]
    view = View(eye=(0.0, 2.2, 6.0), target=(0.0, 0.6, -2.0), fov_deg=55.0)
    levels = (tuple(parents), p1, p2)
    instances = (_instances(near, 0, 3), _instances(mid, 1, 3), _instances(far, 2, 2))
    return Scene(levels, (3, 3, 2), view, instances)


def scene_frame_edge() -> Scene:
    """One agent walking across the left edge of the frame (about half of it outside)."""
    parents = walker_skeleton().parents
    view = View(eye=(0.0, 1.2, 3.0), target=(0.0, 1.0, 0.0), fov_deg=60.0)
    # At 3 m the half-width of the view is 3 · tan(30°) · 4/3 ≈ 2.31 m: x = -2.3 straddles it.
    agent = place(walk_poses()[8], -2.3, 0.0, np.pi / 2)
    return Scene((parents,), (2,), view, (_instances([agent], 0, 2),))


def walk_points() -> np.ndarray:
    """Joints then End Sites ``(F, 19 + 3, 3)`` of one walker gait cycle, root above the
    origin: the points a skinned level reads (:func:`jcrowd.motion.skinning.frames_from_points`)."""
    motion, _ = procedural_walk(cycles=1, fps=30.0, seed=3)
    rot, pos = forward_kinematics(motion.skeleton, motion.rotations, motion.root_positions)
    ends = end_site_positions(motion.skeleton, rot, pos)
    pts = np.concatenate([np.asarray(pos, np.float64), np.asarray(ends, np.float64)], axis=1)
    return pts - pts[:, :1] * np.array([1.0, 0.0, 1.0])


def body_level() -> SkinnedLevel:
    """The shipped body bound to the walker skeleton, every joint kept."""
    skeleton = walker_skeleton()
    bound = bind_body(load_body(body_path()), skeleton, rest_forward(skeleton))
    return skeleton_level(bound, skeleton)


def scene_bodies() -> Scene:
    """Three walking skinned bodies in fixed clothes at 2–6 m (fine, middle and coarse meshes
    by size on screen), the sky, the ground and their blob shadows."""
    skeleton = walker_skeleton()
    points = walk_points()
    agents = [
        place(points[0], -0.6, 1.8, 0.4),
        place(points[12], 0.9, -0.5, -0.6),
        place(points[22], -0.4, -2.5, 1.3),
    ]
    view = View(eye=(0.0, 1.6, 4.2), target=(0.0, 0.9, 0.0), fov_deg=55.0)
    joints = np.stack(agents).astype(np.float32)
    colors = np.array(
        [
            [(0.89, 0.69, 0.56), (0.80, 0.22, 0.20), (0.18, 0.24, 0.38)],
            [(0.49, 0.34, 0.25), (0.93, 0.73, 0.24), (0.15, 0.15, 0.16)],
            [(0.66, 0.48, 0.37), (0.20, 0.36, 0.62), (0.42, 0.38, 0.32)],
        ],
        np.float32,
    )
    heights = np.full(3, character_height(skeleton), np.float32)
    inst = LevelInstances(joints, np.ones(3, bool), colors, heights)
    parents = (*skeleton.parents, *skeleton.end_parents)
    return Scene((parents,), (3,), view, (inst,), bodies=(body_level(),), sky=True)


SCENES: dict[str, Callable[[], Scene]] = {
    "tpose": scene_tpose,
    "three_levels": scene_three_levels,
    "frame_edge": scene_frame_edge,
    "bodies": scene_bodies,
}


def render_scene(ctx: moderngl.Context, scene: Scene) -> np.ndarray:
    """Render ``scene`` at the golden size with a fresh renderer on ``ctx``."""
    with CrowdRenderer(
        scene.levels,
        WIDTH,
        HEIGHT,
        capacity=scene.capacity,
        ctx=ctx,
        bodies=scene.bodies,
        sky=scene.sky,
    ) as r:
        return r.render(scene.view, scene.instances)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_golden(ctx: moderngl.Context, name: str, tmp_path: Path) -> None:
    path = GOLDEN / f"{name}.png"
    if not path.exists():
        pytest.fail(f"{path} is missing: run `python scripts/make_golden.py`")
    golden = iio.imread(path)
    image = render_scene(ctx, SCENES[name]())
    assert image.shape == golden.shape == (HEIGHT, WIDTH, 3)
    diff = np.abs(image.astype(np.int16) - golden.astype(np.int16)).max(axis=-1)
    failing = float(np.mean(diff > PIXEL_TOL))
    if failing > IMAGE_TOL:
        write_png(tmp_path / f"{name}.png", image)
        pytest.fail(
            f"{name}: {failing:.2%} of pixels differ by more than {PIXEL_TOL}/255 (max "
            f"{diff.max()}); rendered image in {tmp_path}. If the change is intended, "
            "regenerate with `python scripts/make_golden.py`."
        )


def test_scenes_are_not_trivial(ctx: moderngl.Context) -> None:
    # Guards the goldens themselves (a golden of an empty frame would pass against an empty
    # render): each level of each scene covers pixels of its own colour. Shading only scales a
    # colour, so its direction in RGB (chromaticity) stays within 0.02 where a bone fully covers
    # a pixel; edge pixels blend with the ground and are not counted. The far level-2 agent is
    # thin (≈ 0.7 px radius) and fully covers only a handful of pixels, hence the bar of 4.
    for name, make in SCENES.items():
        scene = make()
        image = render_scene(ctx, scene).astype(np.float64) / 255.0
        chroma = image / (np.linalg.norm(image, axis=-1, keepdims=True) + 1e-9)
        if scene.bodies is not None:  # each body's shirt colour
            tops = [np.asarray(c)[1] for inst in scene.instances for c in inst.colors]
        else:
            tops = [LEVEL_COLORS[level] for level in range(len(scene.levels))]
        for k, top in enumerate(tops):
            hue = top / np.linalg.norm(top)
            count = int(np.sum(np.linalg.norm(chroma - hue, axis=-1) < 0.02))
            assert count >= 4, f"{name}: colour {k} covers {count} pixels"
