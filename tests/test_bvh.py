"""jcrowd.io.bvh: round trips on every shared clip, Euler orders against SciPy, an independent
parser (PyPI ``bvh``) on written files, atomic writes, unit detection, and one test per kind of
malformed file (each checking the ``file.bvh:LINE`` it cites).

Tolerances used throughout (stated once, used by name):

- ``LENGTH_TOL`` 1e-6 m: lengths are stored float32 (spacing ~1e-7 m at 1 m) and written with 6
  decimals of file units (≤ 5e-7 m when the unit is metres).
- ``ANGLE_TOL`` 1e-4°: rotations are stored as float32 quaternions, ~1e-5° of round-off (more
  near gimbal lock when compared as Euler angles); the angle between two quaternions is taken in
  float64 after normalising them.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest
from bvh import Bvh
from scipy.spatial.transform import Rotation

from jcrowd.errors import BVHError, JcrowdError
from jcrowd.io import UNIT_SCALES, BVHClip, load_bvh, read_bvh, write_bvh
from jcrowd.motion import EULER_ORDERS, Motion, Skeleton, quat_angle, quat_to_euler

LENGTH_TOL = 1e-6  # metres; see the module docstring
ANGLE_TOL = 1e-4  # degrees; see the module docstring

# A small valid file (centimetres, 170 cm tall). Line numbers matter to the error tests:
# 5 root CHANNELS, 6 JOINT Spine, 9 Spine CHANNELS, 13 Head CHANNELS, 20 JOINT LeftLeg,
# 29 root '}', 30 MOTION, 31 Frames, 32 Frame Time, 33-35 frames.
SMALL = """\
HIERARCHY
ROOT Hips
{
\tOFFSET 0.0 90.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Spine
\t{
\t\tOFFSET 0.0 10.0 0.0
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0.0 60.0 0.0
\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.0 10.0 0.0
\t\t\t}
\t\t}
\t}
\tJOINT LeftLeg
\t{
\t\tOFFSET 10.0 -5.0 0.0
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0.0 -85.0 0.0
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.0333333
1.0 2.0 3.0 10.0 20.0 30.0 1.0 2.0 3.0 4.0 5.0 6.0 7.0 8.0 9.0
1.5 2.5 3.5 -10.0 45.0 170.0 0.0 0.0 0.0 -4.0 -5.0 -6.0 70.0 -80.0 90.0
2.0 3.0 4.0 0.0 0.0 0.0 11.0 12.0 13.0 14.0 15.0 16.0 17.0 18.0 19.0
"""


# ----------------------------------------------------------------------------- helpers


def _write(tmp_path: Path, text: str, name: str = "small.bvh") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode())
    return path


def _edit_line(line_no: int, new: str | None) -> str:
    """SMALL with 1-based line ``line_no`` replaced (or removed when ``new`` is None)."""
    lines = SMALL.splitlines()
    lines[line_no - 1 : line_no] = [] if new is None else [new]
    return "\n".join(lines) + "\n"


def _unit(q: object) -> np.ndarray:
    q64 = np.asarray(q, np.float64)
    return q64 / np.linalg.norm(q64, axis=-1, keepdims=True)


def _angle_deg(a: object, b: object) -> np.ndarray:
    """Rotation angle between quaternions, in degrees, computed in float64."""
    return np.degrees(quat_angle(_unit(a), _unit(b)))


def _scipy_quat(order: str, angles_deg: np.ndarray) -> np.ndarray:
    """SciPy's intrinsic Euler → quaternion, as (w, x, y, z)."""
    xyzw = Rotation.from_euler(order, angles_deg, degrees=True).as_quat()
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)


def _wrap(deg: np.ndarray) -> np.ndarray:
    return (deg + 180.0) % 360.0 - 180.0


def _canonical_euler(deg: np.ndarray) -> np.ndarray:
    """The equivalent Tait–Bryan triple with the middle angle in [-90°, 90°]."""
    a, b, c = np.moveaxis(deg, -1, 0)
    b = _wrap(b)
    flip = np.abs(b) > 90.0  # R_i(a) R_j(b) R_k(c) = R_i(a+180) R_j(±180-b) R_k(c+180)
    a, c = np.where(flip, a + 180.0, a), np.where(flip, c + 180.0, c)
    b = np.where(flip, np.sign(b) * 180.0 - b, b)
    return np.stack([a, b, c], axis=-1)


def _file_values(path: Path, frames: int) -> np.ndarray:
    """The frame values of a file by the plainest parse there is: ``(frames, channels)``."""
    text = path.read_text()
    return np.array(text[text.index("Frame Time") :].split()[3:], np.float64).reshape(frames, -1)


def _assert_same_motion(a: Motion, b: Motion, label: str) -> None:
    assert b.skeleton.names == a.skeleton.names, label
    assert b.skeleton.parents == a.skeleton.parents, label
    assert b.skeleton.end_parents == a.skeleton.end_parents, label
    assert b.num_frames == a.num_frames, label
    assert b.fps == pytest.approx(a.fps, rel=1e-9), label  # Frame Time written with 10 digits
    for x, y in [
        (a.skeleton.offsets, b.skeleton.offsets),
        (a.skeleton.end_offsets_or_empty(), b.skeleton.end_offsets_or_empty()),
        (a.root_positions, b.root_positions),
    ]:
        np.testing.assert_allclose(
            np.asarray(y), np.asarray(x), rtol=0, atol=LENGTH_TOL, err_msg=label
        )
    err = _angle_deg(a.rotations, b.rotations).max()
    assert err < ANGLE_TOL, f"{label}: rotations differ by {err:.2e}°"


def _assert_euler_matches_file(clip: BVHClip, values: np.ndarray) -> int:
    """The clip's rotations, as Euler angles in each joint's order, equal the file's values.

    Frames where the file's middle angle is within 1° of ±90° are skipped: there the first and
    last angles are ill-conditioned (gimbal lock) and only their sum or difference is defined.
    Near that band float32 round-off grows by 1/cos(middle): the largest error on the shared
    clips is 7e-5° (08_01, RThumb, middle angle -88.5°), still inside ``ANGLE_TOL``.
    Returns how many angle triples were compared.
    """
    col, compared = 0, 0
    for j, chans in enumerate(clip.channels):
        rot = [c for c, name in enumerate(chans) if name.endswith("rotation")]
        if len(rot) == 3:
            order = "".join(chans[c][0] for c in rot)
            file_deg = _canonical_euler(values[:, [col + c for c in rot]])
            ours = np.degrees(quat_to_euler(_unit(clip.motion.rotations[:, j]), order))
            ok = np.abs(np.abs(file_deg[:, 1]) - 90.0) > 1.0
            err = np.abs(_wrap(ours - file_deg))[ok]
            assert err.max(initial=0.0) < ANGLE_TOL, f"{clip.path} {chans}: {err.max():.2e}°"
            compared += int(ok.sum())
        col += len(chans)
    return compared


# ----------------------------------------------------------------------------- shared clips


def _round_trip(path: Path, tmp_path: Path) -> BVHClip:
    clip = load_bvh(path)
    out = tmp_path / path.name
    write_bvh(out, clip.motion, channels=clip.channels, scale=clip.scale)
    again = load_bvh(out)
    assert again.channels == clip.channels and again.units == clip.units
    _assert_same_motion(clip.motion, again.motion, f"{path.name} (original channels)")
    assert _assert_euler_matches_file(again, _file_values(path, clip.motion.num_frames)) > 0
    write_bvh(out, clip.motion)  # metres, default channels
    metres = load_bvh(out)
    assert metres.units == "m" and metres.channels[1] == ("Zrotation", "Yrotation", "Xrotation")
    _assert_same_motion(clip.motion, metres.motion, f"{path.name} (metres, ZYX)")
    return clip


def test_cmu_clips_round_trip(cmu_dir: Path, tmp_path: Path) -> None:
    paths = sorted(cmu_dir.rglob("*.bvh"))
    assert len(paths) == 32
    with open(cmu_dir / "index.csv", newline="") as f:
        frames = {row["file"]: int(row["frames"]) for row in csv.DictReader(f)}
    for path in paths:
        clip = _round_trip(path, tmp_path)
        m = clip.motion
        assert (m.skeleton.num_joints, clip.units, clip.scale) == (31, "cmu", 0.056444), path
        assert abs(m.fps - 120.0) < 1e-3, path  # Frame Time .0083333
        assert clip.channels[0] == (
            "Xposition",
            "Yposition",
            "Zposition",
            "Zrotation",
            "Yrotation",
            "Xrotation",
        )
        assert all(c == ("Zrotation", "Yrotation", "Xrotation") for c in clip.channels[1:]), path
        assert m.num_frames == frames[path.relative_to(cmu_dir).as_posix()], path
        assert m.rotations.dtype == np.float32 and m.root_positions.dtype == np.float32
    assert read_bvh(cmu_dir / "walk" / "07_01.bvh").num_frames == 317  # the T-pose frame is kept


def test_cmu16_clips_round_trip(cmu16_dir: Path, tmp_path: Path) -> None:
    paths = sorted(cmu16_dir.rglob("*.bvh"))
    assert len(paths) == 22
    with open(cmu16_dir / "index.csv", newline="") as f:
        frames = {row["file"]: int(row["frames"]) for row in csv.DictReader(f)}
    for path in paths:
        assert b"\r\n" in path.read_bytes()[:200], path
        clip = _round_trip(path, tmp_path)
        m = clip.motion
        assert (m.skeleton.num_joints, clip.units, clip.scale) == (19, "cm", 0.01), path
        assert abs(m.fps - 30.0) < 1e-3, path
        assert all(c[-3:] == ("Zrotation", "Xrotation", "Yrotation") for c in clip.channels), path
        assert m.num_frames == frames[path.name], path


def test_independent_parser_reads_written_file(cmu16_dir: Path, tmp_path: Path) -> None:
    clip = load_bvh(cmu16_dir / "16_11.bvh")
    out = tmp_path / "out.bvh"
    write_bvh(out, clip.motion, scale=0.01, precision=5)
    other = Bvh(out.read_text())
    m = clip.motion
    assert other.get_joints_names() == list(m.skeleton.names)
    assert other.nframes == m.num_frames
    assert other.frame_time == pytest.approx(1.0 / m.fps, rel=1e-9)
    chans = ["Zrotation", "Yrotation", "Xrotation"]
    # Written values carry 5 decimals (± 5e-6); SciPy's Euler of the same float32 quaternions
    # agrees with ours to ~1e-12, so 1e-5 is the written precision with a 2x margin.
    for j in (0, 4, 12, m.skeleton.num_joints - 1):
        name = m.skeleton.names[j]
        for f in (0, m.num_frames // 2, m.num_frames - 1):
            q = _unit(m.rotations[f, j])
            expect = Rotation.from_quat([*q[1:], q[0]]).as_euler("ZYX", degrees=True)
            got = np.array(other.frame_joint_channels(f, name, chans))
            assert np.abs(_wrap(got - expect)).max() < 1e-5, (name, f)
        assert other.joint_offset(name) == pytest.approx(
            np.asarray(m.skeleton.offsets[j]) / 0.01, abs=1e-5
        )
    pos = other.frames_joint_channels(m.skeleton.names[0], ["Xposition", "Yposition", "Zposition"])
    np.testing.assert_allclose(
        np.array(pos), np.asarray(m.root_positions) / 0.01, rtol=0, atol=1e-4
    )


# ----------------------------------------------------------------------------- orders and channels


def _orders_text(order: str, angles: np.ndarray, positions: np.ndarray) -> str:
    """Three joints, every one in ``order``; the root's position channels between its rotations."""
    r = [f"{a}rotation" for a in order]
    root = [r[0], "Xposition", r[1], "Yposition", "Zposition", r[2]]
    rows = []
    for f in range(len(angles)):
        a = angles[f]
        row = [a[0, 0], *positions[f, :1], a[0, 1], *positions[f, 1:], a[0, 2], *a[1], *a[2]]
        rows.append(" ".join(f"{v:.6f}" for v in row))
    return (
        f"HIERARCHY\nROOT pelvis\n{{\nOFFSET 0 0.9 0\nCHANNELS 6 {' '.join(root)}\n"
        f"JOINT thigh\n{{\nOFFSET 0.1 -0.05 0\nCHANNELS 3 {' '.join(r)}\n"
        f"JOINT shin\n{{\nOFFSET 0 -0.4 0\nCHANNELS 3 {' '.join(r)}\n"
        "End Site\n{\nOFFSET 0 -0.4 0\n}\n}\n}\n}\n"
        f"MOTION\nFrames: {len(angles)}\nFrame Time: 0.01\n" + "\n".join(rows) + "\n"
    )


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_orders_match_scipy_and_round_trip(order: str, tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    angles = rng.uniform(-179.0, 179.0, (5, 3, 3))
    # Middle angles within ±60°: unique Euler angles, and float32 round-off amplified at most 2x.
    angles[..., 1] = rng.uniform(-60.0, 60.0, (5, 3))
    positions = rng.normal(size=(5, 3))
    path = _write(tmp_path, _orders_text(order, angles, positions), "orders.bvh")
    clip = load_bvh(path)
    assert clip.units == "m" and clip.channels[0][1] == "Xposition"
    assert _angle_deg(clip.motion.rotations, _scipy_quat(order, angles)).max() < ANGLE_TOL
    np.testing.assert_allclose(clip.motion.root_positions, positions, rtol=0, atol=LENGTH_TOL)

    out = tmp_path / "again.bvh"
    write_bvh(out, clip.motion, channels=clip.channels)
    again = load_bvh(out)
    assert again.channels == clip.channels
    _assert_same_motion(clip.motion, again.motion, order)
    values = _file_values(out, 5)  # the writer's Euler angles are the ones we started from
    written = np.stack([values[:, [0, 2, 5]], values[:, 6:9], values[:, 9:12]], axis=1)
    assert np.abs(_wrap(written - angles)).max() < ANGLE_TOL


def test_missing_and_absent_rotation_axes(tmp_path: Path) -> None:
    """Spine has only Y and X rotation channels (Z reads as 0°), Head has none (identity)."""
    lines = SMALL.splitlines()
    lines[8], lines[12] = "CHANNELS 2 Yrotation Xrotation", "CHANNELS 0"
    spine = np.array([[5.0, 6.0], [-7.0, 120.0], [0.0, 0.0]])  # |middle| > 90° is fine too
    lines[32:35] = [f"1 2 3 10 20 30 {y} {x} 7 8 9" for y, x in spine]
    clip = load_bvh(_write(tmp_path, "\n".join(lines) + "\n"))
    assert _angle_deg(clip.motion.rotations[:, 1], _scipy_quat("YX", spine)).max() < ANGLE_TOL
    assert _angle_deg(clip.motion.rotations[:, 2], np.array([1.0, 0.0, 0.0, 0.0])).max() < ANGLE_TOL
    out = tmp_path / "out.bvh"
    write_bvh(out, clip.motion, channels=clip.channels)
    _assert_same_motion(clip.motion, load_bvh(out).motion, "2 and 0 rotation channels")
    # Spine turns about Y, which channels with only Xrotation cannot hold.
    chans = [clip.channels[0], ("Xrotation",), (), clip.channels[3]]
    with pytest.raises(BVHError, match=r"out\.bvh.*'Spine' turns .* about an axis"):
        write_bvh(out, clip.motion, channels=chans)


def test_constant_position_channels_join_the_offset(tmp_path: Path) -> None:
    lines = _edit_line(9, "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
    lines = lines.splitlines()
    for k in (32, 33, 34):  # 0-based rows of the frames: Spine's positions after the root's values
        vals = lines[k].split()
        lines[k] = " ".join([*vals[:6], "0.5", "-1.0", "2.0", *vals[6:]])
    clip = load_bvh(_write(tmp_path, "\n".join(lines) + "\n"))
    np.testing.assert_allclose(
        clip.motion.skeleton.offsets[1], [0.005, 0.09, 0.02], atol=LENGTH_TOL
    )
    out = tmp_path / "out.bvh"
    write_bvh(out, clip.motion, channels=clip.channels, scale=0.01)
    _assert_same_motion(clip.motion, load_bvh(out).motion, "constant positions")
    lines[33] = lines[33].replace(" 0.5 -1.0 2.0 ", " 0.7 -1.0 2.0 ", 1)
    with pytest.raises(
        BVHError, match=r"small\.bvh:9: expected constant Xposition on joint 'Spine'"
    ):
        load_bvh(_write(tmp_path, "\n".join(lines) + "\n"))


def test_depth_first_order_when_writing(tmp_path: Path) -> None:
    """A skeleton in breadth-first order is written depth first; each joint keeps its rotation."""
    offsets = np.array(
        [[0, 1, 0], [0.1, 0, 0], [-0.1, 0, 0], [0, -0.5, 0], [0, -0.5, 0]], np.float32
    )
    sk = Skeleton(
        ("root", "a", "b", "a1", "b1"),
        (-1, 0, 0, 1, 2),
        offsets,
        (3,),
        np.zeros((1, 3), np.float32),
    )
    rot = _scipy_quat("ZYX", np.random.default_rng(1).uniform(-60, 60, (4, 5, 3))).astype(
        np.float32
    )
    motion = Motion(sk, rot, np.zeros((4, 3), np.float32), 25.0)
    write_bvh(tmp_path / "bfs.bvh", motion)
    back = read_bvh(tmp_path / "bfs.bvh")
    perm = [0, 1, 3, 2, 4]
    assert back.skeleton.names == ("root", "a", "a1", "b", "b1")
    assert back.skeleton.parents == (-1, 0, 1, 0, 3) and back.skeleton.end_parents == (2,)
    np.testing.assert_allclose(back.skeleton.offsets, offsets[perm], atol=LENGTH_TOL)
    assert _angle_deg(back.rotations, rot[:, perm]).max() < ANGLE_TOL


def test_tolerated_layout_reads_the_same(tmp_path: Path) -> None:
    """CRLF, extra blanks and tabs, '.0333', frames split across lines, trailing blank lines."""
    base = load_bvh(_write(tmp_path, SMALL))
    head, data = SMALL.split("Frame Time: 0.0333333\n")
    tokens = data.split()
    reflowed = "\n\n".join(" \t ".join(tokens[i : i + 7]) for i in range(0, len(tokens), 7))
    text = (
        head.replace("\tJOINT", "\n   \tJOINT  ") + "Frame Time:\t.0333333\n" + reflowed + "\n\n\n"
    )
    odd = load_bvh(_write(tmp_path, text.replace("\n", "\r\n"), "odd.bvh"))
    _assert_same_motion(base.motion, odd.motion, "odd layout")
    assert base.motion.fps == pytest.approx(30.0, rel=1e-5) and base.units == "cm"
    assert base.motion.skeleton.end_parents == (2, 3)


# ----------------------------------------------------------------------------- atomic writes


def _small_motion(tmp_path: Path) -> Motion:
    return read_bvh(_write(tmp_path, SMALL))


def test_write_into_missing_folder_fails_cleanly(tmp_path: Path) -> None:
    motion = _small_motion(tmp_path)
    before = sorted(tmp_path.iterdir())
    with pytest.raises(BVHError, match=r"missing[/\\]out\.bvh: cannot write"):
        write_bvh(tmp_path / "missing" / "out.bvh", motion)
    assert sorted(tmp_path.iterdir()) == before


@pytest.mark.parametrize("failing", ["fsync", "replace"])
def test_failed_write_keeps_target_and_leaves_no_temp(
    failing: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = _small_motion(tmp_path)
    target = tmp_path / "out.bvh"
    target.write_text("old contents\n")
    before = sorted(tmp_path.iterdir())

    def boom(*args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, failing, boom)
    with pytest.raises(BVHError, match=r"out\.bvh: cannot write: No space left"):
        write_bvh(target, motion)
    monkeypatch.undo()
    assert target.read_text() == "old contents\n"
    assert sorted(tmp_path.iterdir()) == before


def test_interrupted_write_is_reraised_without_temp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = _small_motion(tmp_path)
    before = sorted(tmp_path.iterdir())

    def interrupt(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_bvh(tmp_path / "new.bvh", motion)
    monkeypatch.undo()
    assert sorted(tmp_path.iterdir()) == before


def test_written_file_is_not_private(tmp_path: Path) -> None:
    write_bvh(tmp_path / "out.bvh", _small_motion(tmp_path))
    assert (tmp_path / "out.bvh").stat().st_mode & 0o777 == 0o644


def test_bad_motion_or_arguments_write_nothing(tmp_path: Path) -> None:
    motion = _small_motion(tmp_path)
    nan = Motion(motion.skeleton, motion.rotations * np.nan, motion.root_positions, motion.fps)
    with pytest.raises(BVHError, match=r"out\.bvh.*expected finite"):
        write_bvh(tmp_path / "out.bvh", nan)
    with pytest.raises(BVHError, match=r"expected scale"):
        write_bvh(tmp_path / "out.bvh", motion, scale=0.0)
    with pytest.raises(BVHError, match=r"expected channels for 4 joints, found 1"):
        write_bvh(tmp_path / "out.bvh", motion, channels=[("Xrotation",)])
    with pytest.raises(BVHError, match=r"joint 'Spine'.*found 'Wrotation'"):
        write_bvh(tmp_path / "out.bvh", motion, channels=[(), ("Wrotation",), (), ()])
    assert not (tmp_path / "out.bvh").exists()


# ----------------------------------------------------------------------------- units


@pytest.mark.parametrize("units", ["m", "cm", "cmu", "in", "mm"])
def test_units_are_detected(units: str, tmp_path: Path) -> None:
    motion = _small_motion(tmp_path)  # 1.70 m tall
    write_bvh(tmp_path / "u.bvh", motion, scale=UNIT_SCALES[units])
    clip = load_bvh(tmp_path / "u.bvh")
    assert (clip.units, clip.scale) == (units, UNIT_SCALES[units])
    _assert_same_motion(motion, clip.motion, units)


def test_explicit_scale_and_absurd_heights(tmp_path: Path) -> None:
    motion = _small_motion(tmp_path)
    path = tmp_path / "u.bvh"
    write_bvh(path, motion, scale=1e-5)  # 170,000 units tall
    with pytest.raises(
        BVHError, match=r"u\.bvh: .*rest-pose height.*found 170000 file units.*scale="
    ):
        load_bvh(path)
    clip = load_bvh(path, scale=1e-5)
    assert clip.units == "custom"
    _assert_same_motion(motion, clip.motion, "custom scale")
    assert load_bvh(path, scale=0.01).units == "cm"
    write_bvh(path, motion, scale=0.2)  # 8.5 units: between metres and CMU units
    with pytest.raises(BVHError, match=r"found 8\.5 file units"):
        load_bvh(path)
    with pytest.raises(BVHError, match=r"expected scale"):
        load_bvh(path, scale=-1.0)


# ----------------------------------------------------------------------------- malformed files

_DATA = SMALL.split("Frame Time: 0.0333333\n")[1]
_MALFORMED = {
    "empty file": ("", r"small\.bvh:1: expected HIERARCHY first, found an empty file"),
    "missing HIERARCHY": (
        _edit_line(1, None),
        r"small\.bvh:1: expected HIERARCHY first, found 'ROOT'",
    ),
    "missing ROOT": (_edit_line(2, ""), r"small\.bvh:3: expected ROOT after HIERARCHY, found '\{'"),
    "hierarchy cut short": (
        "\n".join(SMALL.splitlines()[:12]) + "\n",
        r"small\.bvh:12: truncated file: expected '\}' closing Head",
    ),
    "missing MOTION": (
        "\n".join(SMALL.splitlines()[:29]) + "\n",
        r"small\.bvh:29: expected MOTION after the hierarchy",
    ),
    "values cut short": (
        SMALL[: SMALL.rindex("17.0")],
        r"small\.bvh:35: truncated file: .* = 45 values, found 42",
    ),
    "frame time missing": (
        "\n".join(SMALL.splitlines()[:31]) + "\n",
        r"small\.bvh:31: truncated file: expected 'Frame Time:'",
    ),
    "extra frame": (
        SMALL + _DATA.splitlines()[0] + "\n",
        r"small\.bvh:36: expected 3 frames .* found 60; extra from here",
    ),
    "Frames not a number": (
        _edit_line(31, "Frames: three"),
        r"small\.bvh:31: .*'Frames:', found 'three'",
    ),
    "Frames zero": (
        _edit_line(31, "Frames: 0"),
        r"small\.bvh:31: expected a positive whole number.*'0'",
    ),
    "Frames negative": (
        _edit_line(31, "Frames: -3"),
        r"small\.bvh:31: expected a positive whole number.*'-3'",
    ),
    "Frame Time not a number": (
        _edit_line(32, "Frame Time: fast"),
        r"small\.bvh:32: .*'Frame Time:', found 'fast'",
    ),
    "Frame Time zero": (_edit_line(32, "Frame Time: 0"), r"small\.bvh:32: expected seconds > 0"),
    "Frame Time negative": (
        _edit_line(32, "Frame Time: -0.03"),
        r"small\.bvh:32: expected seconds > 0.*'-0\.03'",
    ),
    "Frame Time NaN": (
        _edit_line(32, "Frame Time: nan"),
        r"small\.bvh:32: expected seconds > 0.*'nan'",
    ),
    "Frames keyword misspelt": (
        _edit_line(31, "Frame: 3"),
        r"small\.bvh:31: expected 'Frames:', found 'Frame:'",
    ),
    "channel count": (
        _edit_line(9, "CHANNELS 3 Zrotation Yrotation"),
        r"small\.bvh:9: expected 3 channel names, found 2",
    ),
    "channel count not a number": (
        _edit_line(9, "CHANNELS Zrotation Yrotation Xrotation"),
        r"small\.bvh:9: expected a channel count after CHANNELS, found 'Zrotation'",
    ),
    "unknown channel": (
        _edit_line(13, "CHANNELS 3 Zrotation Wrotation Xrotation"),
        r"small\.bvh:13: expected channels X/Y/Z \+ position/rotation, found 'Wrotation'",
    ),
    "repeated channel": (
        _edit_line(13, "CHANNELS 3 Zrotation Zrotation Xrotation"),
        r"small\.bvh:13: expected one 'Zrotation', found two",
    ),
    "non-numeric value": (
        SMALL.replace("-80.0", "-8O.0"),
        r"small\.bvh:34: expected a number, found '-8O\.0'",
    ),
    "NaN value": (
        SMALL.replace("12.0", "NaN"),
        r"small\.bvh:35: expected finite values, found 'NaN'",
    ),
    "inf value": (
        SMALL.replace("-80.0", "-inf"),
        r"small\.bvh:34: expected finite values, found '-inf'",
    ),
    "duplicate joint": (
        _edit_line(20, "\tJOINT Spine"),
        r"small\.bvh:20: expected a unique joint name, found 'Spine' \(first on line 6\)",
    ),
    "joint without name": (
        _edit_line(20, "\tJOINT"),
        r"small\.bvh:20: expected a unique joint name, found ''",
    ),
    "misspelt keyword": (
        _edit_line(20, "\tJOINTT LeftLeg"),
        r"small\.bvh:20: .*unknown keyword 'JOINTT'",
    ),
    "JOINT outside braces": (
        SMALL.replace("}\nMOTION", "}\nJOINT Extra\n{\nOFFSET 0 0 0\n}\nMOTION"),
        r"small\.bvh:30: expected JOINT inside braces, found it outside",
    ),
    "second ROOT": (
        SMALL.replace("}\nMOTION", "}\nROOT Other\n{\nOFFSET 0 0 0\n}\nMOTION"),
        r"small\.bvh:30: expected one ROOT, found a second",
    ),
    "JOINT without brace": (
        _edit_line(21, "\t\tOFFSET 1 2 3"),
        r"small\.bvh:21: expected '\{' after JOINT LeftLeg",
    ),
    "extra closing brace": (
        SMALL.replace("}\nMOTION", "}\n}\nMOTION"),
        r"small\.bvh:30: unbalanced braces",
    ),
    "missing closing brace": (
        _edit_line(29, None),
        r"small\.bvh:29: expected '\}' closing Hips before MOTION",
    ),
    "stray opening brace": (
        _edit_line(8, "\t\t{"),
        r"small\.bvh:8: unbalanced braces: found a stray '\{'",
    ),
    "OFFSET short": (
        _edit_line(8, "\t\tOFFSET 0.0 10.0"),
        r"small\.bvh:8: expected 3 finite numbers after OFFSET",
    ),
    "OFFSET not numeric": (
        _edit_line(8, "\t\tOFFSET 0.0 ten 0.0"),
        r"small\.bvh:8: expected 3 finite numbers",
    ),
    "OFFSET missing": (_edit_line(8, ""), r"small\.bvh:19: expected an OFFSET in JOINT Spine"),
    "End Site with channels": (
        _edit_line(16, "CHANNELS 1 Xrotation"),
        r"small\.bvh:16: expected CHANNELS in a joint, found it in an End Site",
    ),
    "End Site misspelt": (
        _edit_line(14, "\t\t\tEnd Sight"),
        r"small\.bvh:14: expected 'End Site', found End 'Sight'",
    ),
    "OFFSET outside": (
        SMALL.replace("}\nMOTION", "}\nOFFSET 0 0 0\nMOTION"),
        r"small\.bvh:30: expected OFFSET in a joint, found it outside",
    ),
}


@pytest.mark.parametrize("case", list(_MALFORMED))
def test_malformed_file_raises_with_location(case: str, tmp_path: Path) -> None:
    text, match = _MALFORMED[case]
    with pytest.raises(BVHError, match=match):
        load_bvh(_write(tmp_path, text))


def test_unreadable_file_names_the_path(tmp_path: Path) -> None:
    with pytest.raises(BVHError, match=r"nope\.bvh: cannot read the file"):
        load_bvh(tmp_path / "nope.bvh")
    with pytest.raises(BVHError, match=r"cannot read the file"):
        load_bvh(tmp_path)  # a folder
    assert issubclass(BVHError, JcrowdError) and issubclass(BVHError, ValueError)
