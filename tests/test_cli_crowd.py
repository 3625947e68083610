"""The crowd commands end to end: run → render → export, demo, and their errors."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from jcrowd.cli import main
from jcrowd.io import read_bvh

ROOT = Path(__file__).resolve().parents[1]

SMALL = """
model = "default"
seed = 5
duration = 1.0
fps = 30
[ground]
center = [0, 0]
size = [60, 60]
[camera]
eye = [0, 6, -25]
target = [0, 0, 0]
fov = 50
width = 320
height = 180
[[groups]]
name = "a"
count = 12
spawn = { shape = "rect", center = [0, -5], size = [10, 6] }
path = { waypoints = [[0, 10], [10, 10]], loop = false }
"""


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, dict]:
    code = main(argv)
    return code, json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("run")
    scene = folder / "small.toml"
    scene.write_text(SMALL)
    out = folder / "run.npz"
    from contextlib import redirect_stdout
    from io import StringIO

    buf = StringIO()
    with redirect_stdout(buf):
        code = main(
            ["run", str(scene), "--steps", "20", "--record", "all", "--out", str(out), "--json"]
        )
    assert code == 0
    return out, json.loads(buf.getvalue())


def test_run_json_keys_and_no_recompiles(recording: tuple[Path, dict]) -> None:
    out, result = recording
    for key in (
        "agents",
        "steps",
        "ms_per_step_median",
        "compile_s",
        "level_histogram",
        "recompiles",
        "crowding_max",
        "out",
    ):
        assert key in result
    assert result["agents"] == 12 and result["steps"] == 20 and result["recompiles"] == 0
    assert result["crowding_max"] == 0  # no avoidance in this scene: no neighbour grid
    assert len(result["level_histogram"]) == 7  # 6 levels + culled
    assert sum(result["level_histogram"]) == pytest.approx(12)
    rec = np.load(out)
    assert rec["position"].shape == (20, 12, 2)
    assert rec["points_0"].shape[2:] == (len(rec["parents"]), 3)
    assert np.all(np.isfinite(rec["position"]))


def test_render_recording_to_png_frames(
    recording: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, _ = recording
    code, result = _json(
        capsys,
        [
            "render",
            str(out),
            "--out",
            str(tmp_path / "frames"),
            "--frames",
            "3",
            "--size",
            "160x120",
            "--json",
        ],
    )
    assert code == 0 and result["frames"] == 3
    pngs = sorted((tmp_path / "frames").glob("*.png"))
    assert len(pngs) == 3
    import imageio.v3 as iio

    img = iio.imread(pngs[0])
    assert img.shape == (120, 160, 3)
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 10  # not a blank frame


def test_render_scenario_to_mp4_by_group(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    code, result = _json(
        capsys,
        [
            "render",
            str(scene),
            "--out",
            str(tmp_path / "v" / "clip.mp4"),
            "--frames",
            "4",
            "--color-by",
            "group",
            "--json",
        ],
    )
    assert code == 0
    assert result["frames"] == 4 and result["size"] == [320, 180]
    assert (tmp_path / "v" / "clip.mp4").stat().st_size > 0
    assert result["ms_per_frame_median"] > 0


def test_render_styles_differ(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Bodies (the default) and capsules draw the same scene differently; both by tint, and
    capsules by level too."""
    import imageio.v3 as iio

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    images = {}
    for style, color in (("body", "tint"), ("capsules", "tint"), ("capsules", "level")):
        folder = tmp_path / f"{style}_{color}"
        code, result = _json(
            capsys,
            [
                "render",
                str(scene),
                "--out",
                str(folder),
                "--frames",
                "2",
                "--size",
                "160x120",
                "--style",
                style,
                "--color-by",
                color,
                "--json",
            ],
        )
        assert code == 0 and result["frames"] == 2
        images[style, color] = iio.imread(sorted(folder.glob("*.png"))[-1]).astype(int)
    for a, b in (
        (("body", "tint"), ("capsules", "tint")),
        (("capsules", "tint"), ("capsules", "level")),
    ):
        changed = np.abs(images[a] - images[b]).max(axis=-1) > 8
        assert changed.mean() > 0.002, f"{a} and {b} draw alike"


def test_export_agent_to_bvh_round_trips(
    recording: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, _ = recording
    code, result = _json(
        capsys, ["export", str(out), "--agent", "0", "7", "--out-dir", str(tmp_path), "--json"]
    )
    assert code == 0 and len(result["files"]) == 2
    clip = read_bvh(result["files"][1])
    rec = np.load(out)
    assert clip.num_frames == 20
    # The exported root follows the run's root path (x, z) to BVH precision (1e-6 m text).
    np.testing.assert_allclose(
        np.asarray(clip.root_positions)[:, [0, 2]], rec["position"][:, 7], atol=1e-4
    )


def test_export_crowd_to_glb(
    recording: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The whole crowd (or some agents over some frames) as one glTF binary: one skin per
    agent, an animation as long as the frames asked for, the size reported."""
    import pygltflib as gl

    out, _ = recording
    n = np.load(out)["position"].shape[1]
    glb = tmp_path / "crowd.glb"
    code, result = _json(
        capsys, ["export", str(out), "--format", "glb", "--out", str(glb), "--json"]
    )
    assert code == 0 and result["agents"] == n and result["frames"] == 20
    assert result["bytes"] == glb.stat().st_size
    doc = gl.GLTF2().load(str(glb))
    assert len(doc.skins) == n and len(doc.animations) == 1
    code, result = _json(
        capsys,
        [
            "export",
            str(out),
            "--format",
            "glb",
            "--out",
            str(glb),
            "--agents",
            "0",
            "3",
            "--frames",
            "5:15",
            "--json",
        ],
    )
    assert code == 0 and result["agents"] == 2 and result["frames"] == 10
    doc = gl.GLTF2().load(str(glb))
    assert len(doc.skins) == 2
    assert doc.accessors[doc.animations[0].samplers[0].input].count == 10
    code, result = _json(
        capsys,
        ["export", str(out), "--format", "glb", "--out", str(glb), "--frames", "9:3", "--json"],
    )
    assert code == 2 and "--frames" in result["error"]["message"]


def test_export_needs_a_full_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    main(["run", str(scene), "--steps", "2", "--out", str(tmp_path / "r.npz"), "--json"])
    capsys.readouterr()
    code, result = _json(
        capsys,
        ["export", str(tmp_path / "r.npz"), "--agent", "0", "--out-dir", str(tmp_path), "--json"],
    )
    assert code == 2 and "--record all" in result["error"]["message"]


def test_run_bad_scenario_names_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "bad.toml"
    scene.write_text(SMALL.replace("count = 12", "count = -3"))
    code, result = _json(capsys, ["run", str(scene), "--json"])
    assert code == 2
    assert "bad.toml" in result["error"]["message"]
    assert "groups[0].count" in result["error"]["message"]


@pytest.mark.slow
def test_demo_writes_mp4_and_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, result = _json(
        capsys,
        ["demo", "--out-dir", str(tmp_path), "--seconds", "0.2", "--size", "320x180", "--json"],
    )
    assert code == 0
    assert Path(result["mp4"]).stat().st_size > 0 and Path(result["png"]).stat().st_size > 0
    assert result["agents"] == 3000 and result["frames"] == 6


def test_shipped_demo_scenario_is_the_example() -> None:
    shipped = (ROOT / "jcrowd" / "assets" / "plaza.toml").read_text()
    assert shipped == (ROOT / "examples" / "plaza.toml").read_text()


def test_dots_are_recorded_and_drawn(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With a huge ``min_pixels`` every agent in view is a dot: recorded, counted and drawn."""
    import imageio.v3 as iio

    scene = tmp_path / "dots.toml"
    scene.write_text(SMALL.replace("[[groups]]", "[lod]\nmin_pixels = 1000\n[[groups]]"))
    out = tmp_path / "run.npz"
    code, result = _json(
        capsys,
        ["run", str(scene), "--steps", "3", "--record", "visible", "--out", str(out), "--json"],
    )
    assert code == 0 and result["dots_per_step"] > 0
    assert result["level_histogram"][-1] == pytest.approx(12)  # nobody synthesized
    rec = dict(np.load(out))
    assert rec["dots"].shape == (3, 12) and rec["dots"].any()
    no_dots = tmp_path / "no_dots.npz"
    np.savez(no_dots, **{**rec, "dots": np.zeros_like(rec["dots"])})
    images = []
    for name, src in (("with", out), ("without", no_dots)):
        code, _ = _json(
            capsys,
            ["render", str(src), "--out", str(tmp_path / name), "--frames", "1", "--json"],
        )
        assert code == 0
        images.append(iio.imread(sorted((tmp_path / name).glob("*.png"))[0]).astype(int))
    # The dots are the only difference: some pixels change, most (ground, sky) do not.
    changed = np.any(images[0] != images[1], axis=-1).mean()
    assert 0 < changed < 0.2


@pytest.mark.slow
def test_run_on_two_cpu_devices_records_the_same_crowd(tmp_path: Path) -> None:
    """`jcrowd run --cpu-devices 2` (a fresh process: the option must precede JAX's start) runs
    the crowd split over two CPU devices and records what one device records (nothing overflows
    in this small scene, so the per-device budget does not bind; 1e-5 m, as the sharded tests)."""
    import subprocess
    import sys

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    outs = {}
    for k in (1, 2):
        cmd = [sys.executable, "-m", "jcrowd.cli", "run", str(scene), "--steps", "8", "--json"]
        cmd += ["--cpu-devices", str(k), "--out", str(tmp_path / f"run{k}.npz")]
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        outs[k] = json.loads(done.stdout)
    assert outs[1]["devices"] == 1 and outs[2]["devices"] == 2
    assert outs[2]["recompiles"] == 0 and outs[2]["agents"] == 12
    one, two = np.load(tmp_path / "run1.npz"), np.load(tmp_path / "run2.npz")
    np.testing.assert_allclose(two["position"], one["position"], atol=1e-5)
    np.testing.assert_array_equal(two["level"], one["level"])


def test_cpu_devices_after_jax_started_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import jax

    # The option writes XLA_FLAGS; restore it after the test so later subprocesses (which
    # inherit this environment) are not asked for 3 devices.
    monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))

    jax.devices()  # this test process has started JAX on one CPU device
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    code = main(["run", str(scene), "--steps", "2", "--cpu-devices", "3", "--json"])
    assert code != 0
    err = capsys.readouterr().err
    assert "--cpu-devices: expected 3 CPU devices, found 1" in err


@pytest.mark.slow
def test_render_on_two_cpu_devices(tmp_path: Path) -> None:
    """`jcrowd render` with the step split over two devices: a level's bucket then holds two
    shares of its capacity, rounded up and at least a chunk each (here more slots than the
    configured capacity), so the renderer must be sized from the frame. It was not: this test
    failed before the fix."""
    import subprocess
    import sys

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
    out = tmp_path / "frames.png"
    cmd = [sys.executable, "-m", "jcrowd.cli", "render", str(scene), "--frames", "2"]
    cmd += ["--size", "160x90", "--out", str(out), "--json"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout)["frames"] == 2
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.png", "frame_00001.png"]


def test_render_a_scenario_from_a_camera_of_ones_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--eye/--target see the scene from a fixed close-up camera: the walkers fill far more of
    the frame than from the scenario's camera 25 m away; one without the other is an error."""
    import imageio.v3 as iio

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    shares = []
    for extra in ([], ["--eye", "0,1.6,-10", "--target", "0,1,-5"]):
        out = tmp_path / f"f{len(extra)}"
        code, _ = _json(
            capsys, ["render", str(scene), "--out", str(out), "--frames", "1", "--json", *extra]
        )
        assert code == 0
        img = iio.imread(sorted(out.glob("*.png"))[0]).astype(int)
        # Walkers are drawn in saturated level colours; the ground and sky are greys.
        shares.append(np.mean(img.max(axis=-1) - img.min(axis=-1) > 60))
    assert shares[1] > 3 * shares[0] > 0, shares
    code = main(["render", str(scene), "--out", str(tmp_path / "x"), "--eye", "0,1,-10"])
    assert code != 0
    assert "--eye and --target" in capsys.readouterr().err
    code = main(
        ["render", str(scene), "--out", str(tmp_path / "x"), "--eye", "0,1", "--target", "0,1,0"]
    )
    assert code != 0
    assert "expected X,Y,Z" in capsys.readouterr().err
