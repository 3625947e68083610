"""Tests of jcrowd.render: camera maths, what the renderer draws, errors, and file output.

Golden images live in ``test_render_golden.py``. Every test here that draws shares one
module-scoped GL context, and the GL error flag is checked after each test.
"""

from __future__ import annotations

import gc
import math
import os
import warnings
from pathlib import Path

import imageio.v2 as iio2
import imageio.v3 as iio
import jax.numpy as jnp
import moderngl
import numpy as np
import pytest
from test_render_golden import LEVEL1_KEEP, place, reduce_skeleton, tpose, walk_poses

from jcrowd.errors import RenderError
from jcrowd.motion import walker_skeleton
from jcrowd.render import (
    GROUP_COLORS,
    LEVEL_COLORS,
    CrowdRenderer,
    LevelInstances,
    LevelMesh,
    VideoWriter,
    View,
    frame_points,
    palette_colors,
    project,
    projection_matrix,
    view_matrix,
    write_png,
)
from jcrowd.render.meshes import OBSTACLE_COLOR, capsule_mesh, prism_mesh

PARENTS = walker_skeleton().parents
W, H = 160, 120
VIEW = View(eye=(0.0, 1.6, 5.0), target=(0.0, 0.9, 0.0), fov_deg=60.0)


def _level(poses: list[np.ndarray], capacity: int, color: int = 0) -> LevelInstances:
    joints = np.zeros((capacity, poses[0].shape[0], 3), np.float32)
    joints[: len(poses)] = np.stack(poses)
    valid = np.arange(capacity) < len(poses)
    return LevelInstances(joints, valid, np.tile(LEVEL_COLORS[color], (capacity, 1)))


def _render(ctx: moderngl.Context, poses: list[np.ndarray], **kwargs: object) -> np.ndarray:
    with CrowdRenderer([PARENTS], W, H, capacity=[4], ctx=ctx, **kwargs) as r:  # type: ignore[arg-type]
        return r.render(VIEW, [_level(poses, 4)])


# --- camera -------------------------------------------------------------------------------


def test_project_closed_form_axis_and_fov_edges() -> None:
    # A camera at (1, 2, 3) looking down -Z: a point on the optical axis lands on the image
    # centre; a point at angle fov/2 above the axis on the top edge (y = 0); a point at the
    # horizontal half-angle atan(tan(fov/2)·W/H) on the right edge (x = W).
    view = View(eye=(1.0, 2.0, 3.0), target=(1.0, 2.0, -7.0), fov_deg=50.0)
    d, t = 4.0, math.tan(math.radians(25.0))
    pts = np.array(
        [(1.0, 2.0, 3.0 - d), (1.0, 2.0 + d * t, 3.0 - d), (1.0 + d * t * W / H, 2.0, 3.0 - d)]
    )
    px, front = project(pts, view, W, H)
    np.testing.assert_allclose(px, [(W / 2, H / 2), (W / 2, 0.0), (W, H / 2)], atol=1e-9)
    assert front.all()


def test_project_turned_camera_and_behind() -> None:
    # Looking along +X with +Y up: the camera's right is +Z (right-handed), so +Z goes right.
    view = View(eye=(0.0, 0.0, 0.0), target=(1.0, 0.0, 0.0), fov_deg=90.0)
    pts = np.array([(5.0, 0.0, 5.0 * W / H), (5.0, -5.0, 0.0), (-2.0, 0.0, 0.0), (0.05, 0, 0)])
    px, front = project(pts, view, W, H)
    np.testing.assert_allclose(px[:2], [(W, H / 2), (W / 2, H)], atol=1e-9)
    assert front.tolist() == [True, True, False, False]  # behind; in front of the near plane
    assert np.all(np.isfinite(px))


def test_view_matrix_is_rigid_and_puts_target_ahead() -> None:
    view = View(eye=(3.0, 4.0, -2.0), target=(-1.0, 0.5, 6.0), up=(0.1, 1.0, 0.0))
    m = view_matrix(view)
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)
    dist = np.linalg.norm(np.subtract(view.target, view.eye))
    np.testing.assert_allclose(m @ [*view.target, 1.0], [0.0, 0.0, -dist, 1.0], atol=1e-12)
    np.testing.assert_allclose(m @ [*view.eye, 1.0], [0.0, 0.0, 0.0, 1.0], atol=1e-12)


def test_projection_maps_near_and_far_to_ndc_bounds() -> None:
    p = projection_matrix(VIEW, W, H)
    for depth, ndc in ((VIEW.near, -1.0), (VIEW.far, 1.0)):
        clip = p @ [0.0, 0.0, -depth, 1.0]
        assert clip[2] / clip[3] == pytest.approx(ndc)


def test_frame_points_fits_everything() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform([-20, 0, -5], [20, 2, 30], size=(200, 3))
    view = frame_points(pts, aspect=W / H)
    px, front = project(pts, view, W, H)
    assert front.all()
    assert np.all((px >= 0) & (px <= [W, H]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"eye": (0, 0, 0), "target": (0, 0, 0)}, "coincide"),
        ({"eye": (0, 0, 0), "target": (0, 5, 0)}, "parallel"),
        ({"eye": (0, 0, 1), "target": (0, 0, 0), "near": 0.0}, "near"),
        ({"eye": (0, 0, 1), "target": (0, 0, 0), "fov_deg": 180.0}, "fov"),
        ({"eye": (0, 0, math.nan), "target": (0, 0, 0)}, "finite"),
    ],
)
def test_view_rejects_bad_cameras(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(RenderError, match=match):
        View(**kwargs)  # type: ignore[arg-type]


# --- meshes and palettes -----------------------------------------------------------------


def test_capsule_mesh_is_closed_and_outward() -> None:
    vertices, tris = capsule_mesh(8, 2)
    # Closed surface: every edge used exactly twice, once in each direction.
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    assert len({tuple(e) for e in edges.tolist()}) == len(edges)
    assert {tuple(e) for e in edges[:, ::-1].tolist()} == {tuple(e) for e in edges.tolist()}
    # Outward winding on a capsule of length 2 along z (centre at z = 1).
    p = vertices[:, :3] + vertices[:, 3:] * np.array([0.0, 0.0, 2.0])
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3 - [0.0, 0.0, 1.0])
    assert np.all(outward > 0)


def test_prism_mesh_is_closed_outward_and_covers_the_area() -> None:
    """A square with a square hole, extruded to 1 m: closed but for its bottom on the ground
    (every other edge twice, once in each direction); each triangle wound counter-clockwise
    seen from outside the solid (its normal points away from the solid: its centroid moved
    1 cm along it leaves the solid); the top's triangles cover the area exactly (shapely's
    area as the oracle)."""
    import shapely

    area = shapely.box(0, 0, 4, 4).difference(shapely.box(1, 1, 2, 2))
    mesh = prism_mesh(area, 1.0).reshape(-1, 3, 6)
    tri, normal = mesh[..., :3].astype(np.float64), mesh[:, 0, 3:]
    geometric = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", geometric, normal) > 0)  # wound to face the normal
    probe = tri.mean(axis=1) + 0.01 * normal
    outside = ~shapely.contains_xy(area, probe[:, 0], probe[:, 2]) | (probe[:, 1] > 1.0)
    assert outside.all()
    keys = np.round(tri, 6)
    edges = [
        tuple(map(tuple, keys[t, [a, b]]))
        for t in range(len(keys))
        for a, b in ((0, 1), (1, 2), (2, 0))
        if keys[t, a, 1] > 0 or keys[t, b, 1] > 0  # the open bottom stands on the ground
    ]
    assert sorted(edges) == sorted((b, a) for a, b in edges)
    top = normal[:, 1] > 0.5
    area_top = 0.5 * np.abs(geometric[top][:, 1]).sum()
    assert area_top == pytest.approx(area.area, rel=1e-9)
    assert len(prism_mesh(shapely.Polygon())) == 0


def test_obstacles_are_drawn_lit_from_above(ctx: moderngl.Context) -> None:
    """A 2 m block in front of the camera covers the pixels its top projects to, in the
    obstacle colour times the shading of an upward face (ambient·1 + (1 − ambient)·l_y, the
    shader's formula with n = +y); without obstacles the same pixel is ground."""
    import shapely

    from jcrowd.render.renderer import _AMBIENT, _LIGHT_DIR

    mesh = prism_mesh(shapely.box(-1, -1, 1, 1), 1.0)
    nobody = LevelInstances(np.zeros((1, len(PARENTS), 3)), np.zeros(1, bool), np.zeros((1, 3)))
    with CrowdRenderer([PARENTS], W, H, capacity=[1], ctx=ctx, samples=0, obstacles=mesh) as r:
        image = r.render(VIEW, [nobody])
    with CrowdRenderer([PARENTS], W, H, capacity=[1], ctx=ctx, samples=0) as r:
        bare = r.render(VIEW, [nobody])
    xy, _ = project(np.array([[0.0, 1.0, -0.5]]), VIEW, W, H)
    col, row = xy[0]
    px = image[int(row), int(col)].astype(float)
    shade = _AMBIENT + (1 - _AMBIENT) * max(_LIGHT_DIR[1], 0.0)
    want = np.clip(np.asarray(OBSTACLE_COLOR) * shade, 0, 1) * 255
    np.testing.assert_allclose(px, want, atol=2.0)  # 8-bit rounding (+1 for the driver)
    assert np.abs(bare[int(row), int(col)].astype(float) - want).max() > 10


def test_palettes() -> None:
    assert len(LEVEL_COLORS) >= 8 and len(GROUP_COLORS) >= 8
    assert LEVEL_COLORS[0, 0] > LEVEL_COLORS[0, 2] and LEVEL_COLORS[6, 2] > LEVEL_COLORS[6, 0]
    # Distinct neighbours: at least 0.15 apart in RGB.
    for pal in (LEVEL_COLORS, GROUP_COLORS):
        assert np.linalg.norm(np.diff(pal, axis=0), axis=-1).min() > 0.15
    np.testing.assert_array_equal(
        palette_colors(np.array([0, 12]), LEVEL_COLORS, cycle=False), LEVEL_COLORS[[0, -1]]
    )
    np.testing.assert_array_equal(palette_colors(np.array([9]), GROUP_COLORS), GROUP_COLORS[[1]])
    with pytest.raises(RenderError, match="non-negative"):
        palette_colors(np.array([-1]), GROUP_COLORS)


# --- what gets drawn ------------------------------------------------------------------------


def _empty(num_joints: int) -> LevelInstances:
    return LevelInstances(
        np.zeros((0, num_joints, 3), np.float32), np.zeros(0, bool), np.zeros((0, 3), np.float32)
    )


@pytest.mark.parametrize("samples", [0, 4])
def test_projected_joints_land_on_drawn_pixels(ctx: moderngl.Context, samples: int) -> None:
    # Joints 3.9–6.6 m deep at 160×120 with fov 60° (focal length 104 px): a 5 cm bone radius
    # projects to 0.78–1.34 px, and a joint's own pixel has its centre ≤ 0.71 px from the
    # joint, so the capsule covers that pixel (with MSAA, most of its samples). Ground off, so
    # every drawn pixel differs from the background. Bar (DESIGN §6): ≥ 99 % (66/66 here).
    poses = walk_poses()
    levels = (PARENTS, reduce_skeleton(PARENTS, LEVEL1_KEEP))
    near = [place(poses[0], -1.0, 1.0, 0.4), place(poses[15], 1.2, 0.5, 2.0)]
    mid = [place(poses[9], -0.6, -1.0, -1.0)[list(LEVEL1_KEEP)], tpose()[list(LEVEL1_KEEP)]]
    mid[1] += [1.8, 0.0, -1.5]
    with CrowdRenderer(levels, W, H, capacity=[3, 2], ctx=ctx, samples=samples, ground=False) as r:
        image = r.render(VIEW, [_level(near, 3), _level(mid, 2, color=1)])
        background = r.render(VIEW, [_empty(len(PARENTS)), _empty(len(LEVEL1_KEEP))])
    assert np.all(background == background[0, 0])
    joints = np.concatenate([np.concatenate(near), np.concatenate(mid)])
    px, front = project(joints, VIEW, W, H)
    inside = front & np.all((px >= 0) & (px < [W, H]), axis=-1)
    assert inside.all()  # the scene is framed so that every joint is visible
    cols, rows = np.floor(px).astype(int).T
    # "Drawn" = differs from the background by more than 8/255 in some channel: rounding moves
    # the background by at most 1, while the lightest capsule shading is far from it.
    drawn = np.abs(image[rows, cols].astype(int) - background[0, 0]).max(-1) > 8
    assert drawn.mean() >= 0.99, f"{(~drawn).sum()} of {len(drawn)} joints on background"


def test_agent_behind_camera_draws_nothing(ctx: moderngl.Context) -> None:
    # The camera at z = 5 looks towards -Z (tilted 8° down): agents at z = 8 and z = 5.5 stand
    # 3 m and 0.5 m behind it, in the mirrored frustum. Neither may draw anything.
    with CrowdRenderer([PARENTS], W, H, capacity=[2], ctx=ctx) as r:
        nothing = r.render(VIEW, [_empty(len(PARENTS))])
        behind = [place(tpose(), 0.0, 8.0), place(tpose(), 0.3, 5.5)]
        image = r.render(VIEW, [_level(behind, 2)])
    _, front = project(np.concatenate(behind), VIEW, W, H)
    assert not front.any()
    np.testing.assert_array_equal(image, nothing)


def test_invalid_slots_draw_nothing_whatever_they_hold(ctx: moderngl.Context) -> None:
    with CrowdRenderer([PARENTS], W, H, capacity=[3], ctx=ctx) as r:
        one = r.render(VIEW, [_level([tpose()], 3)])
        joints = np.full((3, len(PARENTS), 3), np.nan, np.float32)
        joints[1] = tpose()
        padded = LevelInstances(
            joints, np.array([False, True, False]), np.tile(LEVEL_COLORS[0], (3, 1))
        )
        np.testing.assert_array_equal(r.render(VIEW, [padded]), one)


def test_same_input_same_image(ctx: moderngl.Context) -> None:
    poses = [place(p, x, 0.0) for p, x in zip(walk_poses()[::10], (-1.5, 0.0, 1.5), strict=False)]
    first = _render(ctx, poses)
    with CrowdRenderer([PARENTS], W, H, capacity=[4], ctx=ctx) as r:
        second, third = r.render(VIEW, [_level(poses, 4)]), r.render(VIEW, [_level(poses, 4)])
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(second, third)


def test_device_arrays_render_like_numpy(ctx: moderngl.Context) -> None:
    # The crowd step hands over jax arrays; the renderer copies them to the host once.
    level = _level([tpose()], 2)
    on_device = LevelInstances(
        jnp.asarray(level.joints), jnp.asarray(level.valid), jnp.asarray(level.colors)
    )
    with CrowdRenderer([PARENTS], W, H, capacity=[2], ctx=ctx) as r:
        np.testing.assert_array_equal(r.render(VIEW, [on_device]), r.render(VIEW, [level]))


def test_image_orientation_and_colour(ctx: moderngl.Context) -> None:
    # One agent up and to the left of the image centre: its pixels lie in the left half, its
    # top (the arms) where `project` puts the highest joint, so the image is not flipped.
    agent = tpose() + np.array([-1.5, 0.8, 0.0])
    # No MSAA, so no pixel blends with the background: every drawn pixel is the level-0 red
    # (0.86, 0.20, 0.16) times a shade ≥ 0.2, i.e. R ≥ 44 and R ≈ 4.3 G ≈ 5.4 B up to rounding.
    image = _render(ctx, [agent], ground=False, samples=0).astype(int)
    drawn = np.any(image != image[0, -1], axis=-1)
    rows, cols = np.nonzero(drawn)
    px, _ = project(agent, VIEW, W, H)
    assert cols.max() < W / 2 and rows.mean() < H / 2
    assert rows.min() == pytest.approx(px[:, 1].min(), abs=3)  # radius ≈ 1 px, + rounding
    red = image[drawn]
    assert np.all(red[:, 0] >= 44) and np.all(red[:, 0] > 3 * red[:, 1:].max(-1))


# --- bad input --------------------------------------------------------------------------------


def test_render_errors(ctx: moderngl.Context) -> None:
    with CrowdRenderer([PARENTS], W, H, capacity=[2], ctx=ctx) as r:
        good = _level([tpose()], 2)
        bad = np.array(good.joints)
        bad[0, 3, 1] = np.inf
        with pytest.raises(RenderError, match="non-finite joint positions in valid slot 0"):
            r.render(VIEW, [LevelInstances(bad, good.valid, good.colors)])
        with pytest.raises(RenderError, match=r"joints of shape \(C, 19, 3\)"):
            r.render(VIEW, [LevelInstances(bad[:, :5], good.valid, good.colors)])
        with pytest.raises(RenderError, match="capacity is 2"):
            r.render(VIEW, [_level([tpose()] * 3, 3)])
        with pytest.raises(RenderError, match="expected 1 levels, found 2"):
            r.render(VIEW, [good, good])
        with pytest.raises(RenderError, match="valid of shape"):
            r.render(VIEW, [LevelInstances(good.joints, good.valid.astype(int), good.colors)])
        with pytest.raises(RenderError, match="colors of shape"):
            r.render(VIEW, [LevelInstances(good.joints, good.valid, good.colors[:, :2])])
        r.render(VIEW, [good])  # still usable after rejected frames
    with pytest.raises(RenderError, match="released"):
        r.render(VIEW, [good])


def test_constructor_errors(ctx: moderngl.Context) -> None:
    with pytest.raises(RenderError, match="topological"):
        CrowdRenderer([(-1, 2, 0)], capacity=[1], ctx=ctx)
    with pytest.raises(RenderError, match="capacities"):
        CrowdRenderer([PARENTS, PARENTS], capacity=[1], ctx=ctx)
    with pytest.raises(RenderError, match="MSAA"):
        CrowdRenderer([PARENTS], capacity=[1], ctx=ctx, samples=ctx.max_samples * 2)
    with pytest.raises(RenderError, match="bone radius"):
        CrowdRenderer([PARENTS], capacity=[1], ctx=ctx, bone_radius=0.0)
    with pytest.raises(RenderError, match="segments"):
        CrowdRenderer([PARENTS], capacity=[1], ctx=ctx, detail=[(2, 1)])
    with pytest.raises(RenderError, match="capsule details"):
        CrowdRenderer([PARENTS], capacity=[1], ctx=ctx, detail=[(8, 2), (6, 1)])
    assert LevelMesh((-1, 0, 0, 2)).bones[1].tolist() == [1, 2, 3]


def test_coarser_capsules_cover_the_same_place(ctx: moderngl.Context) -> None:
    # A 4-sided, 1-ring capsule is a prism inside the default 8-sided one: it draws fewer
    # pixels, all of them where the default draws (up to anti-aliased edge pixels, ≤ 5 %).
    agent = [tpose()]
    fine = _render(ctx, agent, ground=False, samples=0)
    coarse = _render(ctx, agent, ground=False, samples=0, detail=[(4, 1)])
    drawn_fine = np.any(fine != fine[0, 0], axis=-1)
    drawn_coarse = np.any(coarse != coarse[0, 0], axis=-1)
    assert 0 < drawn_coarse.sum() < drawn_fine.sum()
    assert np.mean(drawn_fine[drawn_coarse]) > 0.95


def test_make_context_names_the_missing_library(monkeypatch: pytest.MonkeyPatch) -> None:
    import jcrowd.render.context as context

    monkeypatch.setattr(context.ctypes.util, "find_library", lambda name: None)
    with pytest.raises(RenderError, match=r"libEGL\.so and libGL\.so not found.*libegl1"):
        context.make_context()


def test_make_context_reports_the_egl_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import jcrowd.render.context as context

    def fail(**kwargs: object) -> None:
        raise Exception("eglInitialize failed (0x3001)")  # what glcontext raises

    monkeypatch.setattr(context.moderngl, "create_context", fail)
    with pytest.raises(RenderError, match=r"eglInitialize failed \(0x3001\).*apt install"):
        context.make_context()


# --- output files -----------------------------------------------------------------------------


def test_write_png_round_trip(tmp_path: Path) -> None:
    image = np.random.default_rng(0).integers(0, 256, size=(30, 40, 3), dtype=np.uint8)
    path = tmp_path / "frame.png"
    write_png(path, image)
    np.testing.assert_array_equal(iio.imread(path), image)
    assert os.listdir(tmp_path) == ["frame.png"]
    with pytest.raises(RenderError, match="uint8"):
        write_png(path, image.astype(np.float32))
    with pytest.raises(RenderError, match="cannot write"):
        write_png(tmp_path / "missing" / "frame.png", image)


def _frames(n: int, w: int = 64, h: int = 48) -> list[np.ndarray]:
    """Frames with a bright square moving right on a dark background."""
    out = []
    for i in range(n):
        f = np.full((h, w, 3), 20, np.uint8)
        f[10:30, 5 + 8 * i : 25 + 8 * i] = (230, 60, 40)
        out.append(f)
    return out


def _read_video(path: Path) -> list[np.ndarray]:
    """All frames of a clip, decoded by imageio's ffmpeg reader."""
    # imageio's reader starts ffmpeg with a preexec_fn (so JAX, initialised in this process,
    # warns about fork) and leaves its pipes to the garbage collector (ResourceWarning). Both
    # are the reader's, not the writer's under test: silenced here only, collected in place.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "os.fork", RuntimeWarning)
        warnings.simplefilter("ignore", ResourceWarning)
        with iio2.get_reader(path, format="FFMPEG") as reader:
            frames = list(reader.iter_data())
        gc.collect()
    return frames


def test_mp4_is_readable_and_atomic(tmp_path: Path) -> None:
    # JAX running in the same process (as in `jcrowd render`): starting ffmpeg must not fork
    # with handlers (JAX would warn of deadlocks; warnings are errors here).
    jnp.zeros(3).block_until_ready()
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, fps=10) as video:
        for frame in _frames(5):
            video.append(frame)
            assert not path.exists()  # only the hidden temporary file exists until close
    assert os.listdir(tmp_path) == ["clip.mp4"]
    frames = _read_video(path)
    assert len(frames) == 5
    assert frames[0].shape == (48, 64, 3)
    # H.264 is lossy: compare a flat area inside the square, away from its edges, within
    # 20/255 (crf 20 with chroma subsampling keeps flat colours within a few levels).
    np.testing.assert_allclose(
        frames[2][15:25, 27:37], np.broadcast_to((230, 60, 40), (10, 10, 3)), atol=20
    )


def test_mp4_reports_a_failing_ffmpeg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import jcrowd.render.output as output

    monkeypatch.setattr(output.imageio_ffmpeg, "get_ffmpeg_exe", lambda: "/bin/false")
    with pytest.raises(RenderError, match="ffmpeg"):
        with VideoWriter(tmp_path / "clip.mp4") as video:
            for frame in _frames(3):
                video.append(frame)
    assert os.listdir(tmp_path) == []


def test_gif_is_readable(tmp_path: Path) -> None:
    path = tmp_path / "clip.gif"
    with VideoWriter(path, fps=5) as video:
        for frame in _frames(3):
            video.append(frame)
    frames = iio.imread(path, index=None)
    assert frames.shape[:3] == (3, 48, 64)
    assert os.listdir(tmp_path) == ["clip.gif"]


def test_video_errors_leave_no_file(tmp_path: Path) -> None:
    with pytest.raises(RenderError, match="even width and height"):
        with VideoWriter(tmp_path / "odd.mp4") as video:
            video.append(np.zeros((47, 64, 3), np.uint8))
    with pytest.raises(RenderError, match="frame 1 is 32×48"):
        with VideoWriter(tmp_path / "sizes.mp4") as video:
            video.append(np.zeros((48, 64, 3), np.uint8))
            video.append(np.zeros((48, 32, 3), np.uint8))
    with pytest.raises(RuntimeError, match="boom"):
        with VideoWriter(tmp_path / "raised.mp4") as video:
            video.append(np.zeros((48, 64, 3), np.uint8))
            raise RuntimeError("boom")
    with pytest.raises(RenderError, match="no frames"):
        with VideoWriter(tmp_path / "empty.gif"):
            pass
    with pytest.raises(RenderError, match=r"\.mp4 or \.gif"):
        VideoWriter(tmp_path / "clip.avi")
    assert os.listdir(tmp_path) == []
