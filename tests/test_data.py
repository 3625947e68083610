"""Datasets and the procedural walker: loading with labels and errors, and a walker whose
control parameters are known exactly, recovered by gait analysis."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

from jcrowd.errors import BVHError, DataError, MotionError
from jcrowd.io import load_dataset, write_bvh
from jcrowd.motion import (
    bone_lengths,
    end_site_positions,
    foot_contacts,
    forward_kinematics,
    gait_cycles,
    joint_bone_lengths,
    procedural_walk,
    rest_positions,
    walker_skeleton,
)
from jcrowd.motion.clip import Clip, headings, left_right_pairs, rest_forward

DEG = np.pi / 180


def _world(motion):  # joints and End Sites in float64 world coordinates
    rot = np.asarray(motion.rotations, np.float64)
    root = np.asarray(motion.root_positions, np.float64)
    g, p = forward_kinematics(motion.skeleton, rot, root)
    return p, end_site_positions(motion.skeleton, g, p)


# ----------------------------------------------------------------------------- the walker


@pytest.mark.parametrize("height", [1.5, 1.75, 1.95])
def test_walker_skeleton_has_the_asked_height_and_faces_z(height: float) -> None:
    sk = walker_skeleton(height)
    joints, ends = rest_positions(sk)
    ys = np.concatenate([joints[:, 1], ends[:, 1]])
    head_top = ends[list(sk.end_parents).index(sk.index("Head")), 1]
    # float32 offsets summed over ~6 bones: 1e-3 m is far above round-off, far below a bone.
    assert abs(head_top - ys.min() - height) < 1e-3
    assert 15 <= sk.num_joints <= 19
    assert len(left_right_pairs(sk.names)) == 7  # legs (4) and arms (3) pair up by name
    np.testing.assert_allclose(rest_forward(sk), [0.0, 0.0, 1.0], atol=1e-9)
    assert joints[sk.index("LeftUpLeg"), 0] > 0 > joints[sk.index("RightUpLeg"), 0]
    # End Sites at both toe tips and the head top.
    assert sorted(sk.names[p] for p in sk.end_parents) == ["Head", "LeftToe", "RightToe"]


WALKS = [
    dict(),
    dict(dyaw_per_cycle=90 * DEG, fps=30.0),
    dict(dyaw_per_cycle=-45 * DEG, speed=1.6, height=1.6),
]


@pytest.mark.parametrize("kw", WALKS)
def test_planted_feet_do_not_move(kw: dict) -> None:
    motion, truth = procedural_walk(**kw)
    pos, ends = _world(motion)
    sk = motion.skeleton
    feet = [
        (
            truth.contacts[:, 0],
            [pos[:, sk.index("LeftFoot")], pos[:, sk.index("LeftToe")], ends[:, 0]],
        ),
        (
            truth.contacts[:, 1],
            [pos[:, sk.index("RightFoot")], pos[:, sk.index("RightToe")], ends[:, 1]],
        ),
    ]
    for planted, points in feet:
        both = planted[1:] & planted[:-1]
        assert both.sum() > 0.5 * len(both)  # stance is ~60 % of the time
        for p in points:
            step = np.linalg.norm(p[1:] - p[:-1], axis=-1)
            # The brief's bound: 2 mm; FK in float32 gives ~1e-6 m, so a real slip shows.
            assert step[both].max() < 2e-3
            # Flat on the ground: a planted point is at its lowest height (±1 mm).
            assert np.ptp(p[planted, 1]) < 1e-3
            assert p[planted, 1].min() - p[:, 1].min() < 1e-3
    # Toes touch the ground (y = 0) in stance, and nothing goes below it.
    assert abs(ends[:, :2, 1].min()) < 1e-3


@pytest.mark.parametrize("kw", WALKS)
def test_bones_keep_their_lengths(kw: dict) -> None:
    motion, _ = procedural_walk(**kw)
    pos, _ = _world(motion)
    posed = joint_bone_lengths(motion.skeleton, pos)
    rest = np.asarray(bone_lengths(motion.skeleton), np.float64)
    # float32 rotations and offsets: ~1e-7 m of round-off per bone, well inside 1e-5 m.
    np.testing.assert_allclose(posed, np.broadcast_to(rest, posed.shape), atol=1e-5)


@pytest.mark.parametrize("dyaw", [0.0, 30 * DEG, -90 * DEG])
def test_root_follows_the_closed_form_arc(dyaw: float) -> None:
    speed, period, lead_in = 1.25, 1.05, 0.25
    motion, truth = procedural_walk(
        cycles=2, speed=speed, dyaw_per_cycle=dyaw, cycle_duration=period, lead_in=lead_in
    )
    end_t = (motion.num_frames - 1) / motion.fps
    # Oracle 1: the arc's closed form at the last frame, started at the origin facing +Z.
    length, theta = speed * end_t, dyaw / period * end_t
    closed = (
        [length * (1 - np.cos(theta)) / theta, length * np.sin(theta) / theta]
        if theta
        else [0.0, length]
    )
    # Oracle 2: integrate the unit-speed heading numerically (midpoint rule, 1e5 steps).
    n = 100_000
    psi = dyaw / period * (np.arange(n) + 0.5) * end_t / n
    numeric = [np.sum(np.sin(psi)) * speed * end_t / n, np.sum(np.cos(psi)) * speed * end_t / n]
    root = np.asarray(motion.root_positions[-1], np.float64)
    # float32 root positions of a few metres: ~1e-6 m; 1e-5 m leaves room and catches any error.
    np.testing.assert_allclose(root[[0, 2]], closed, atol=1e-5)
    np.testing.assert_allclose(root[[0, 2]], numeric, atol=1e-5)
    # Heading = path tangent; the truth per cycle = the root's own displacement between strikes.
    yaw = np.unwrap(np.asarray(headings(motion), np.float64))
    t = np.arange(motion.num_frames) / motion.fps
    np.testing.assert_allclose(yaw, dyaw / period * t, atol=1e-5)
    f = truth.strike_frames
    np.testing.assert_allclose(f / motion.fps, truth.left_strikes, atol=1e-9)
    for i in range(truth.num_cycles):
        d = np.asarray(motion.root_positions[f[i + 1]] - motion.root_positions[f[i]], np.float64)
        c, s = np.cos(yaw[f[i]]), np.sin(yaw[f[i]])
        np.testing.assert_allclose(
            [c * d[0] - s * d[2], s * d[0] + c * d[2]], [truth.dx[i], truth.dz[i]], atol=1e-5
        )
        assert abs(yaw[f[i + 1]] - yaw[f[i]] - truth.dyaw[i]) < 1e-5
    assert (
        truth.num_cycles == 2 and np.all(truth.speed == speed) and np.all(truth.duration == period)
    )
    # The tail holds the last strike with at least 0.3 s after it.
    assert end_t - truth.left_strikes[-1] >= 0.3 - 1e-9


def test_truth_has_the_straight_limit() -> None:
    _, straight = procedural_walk(speed=1.2, cycle_duration=1.0)
    _, tiny = procedural_walk(speed=1.2, cycle_duration=1.0, dyaw_per_cycle=1e-7)
    assert straight.dx[0] == 0.0 and straight.dz[0] == pytest.approx(1.2, abs=1e-12)
    assert tiny.dx[0] == pytest.approx(0.0, abs=1e-7) and tiny.dz[0] == pytest.approx(1.2, abs=1e-9)


def test_walker_is_deterministic_and_the_seed_only_changes_style() -> None:
    a, ta = procedural_walk(seed=3, dyaw_per_cycle=0.3)
    b, _ = procedural_walk(seed=3, dyaw_per_cycle=0.3)
    c, tc = procedural_walk(seed=4, dyaw_per_cycle=0.3)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root_positions, b.root_positions)
    assert a.rotations.dtype == np.float32 and a.root_positions.dtype == np.float32
    legs = [a.skeleton.index(n) for n in ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightFoot")]
    np.testing.assert_array_equal(a.rotations[:, legs], c.rotations[:, legs])
    np.testing.assert_array_equal(a.root_positions, c.root_positions)
    assert not np.array_equal(a.rotations, c.rotations)  # arms and chest differ
    for field in ("dx", "dz", "dyaw", "speed", "left_strikes", "contacts"):
        np.testing.assert_array_equal(getattr(ta, field), getattr(tc, field))


@pytest.mark.parametrize(
    ("kw", "words"),
    [
        (dict(cycles=0), "at least one cycle"),
        (dict(speed=-1.0), "non-negative speed"),
        (dict(lead_in=2.0), "lead-in"),
        (dict(speed=4.0), "stride the legs can reach"),
        (dict(height=0.0), "positive height"),
    ],
)
def test_walker_rejects_impossible_walks(kw: dict, words: str) -> None:
    with pytest.raises(MotionError, match=words):
        procedural_walk(**kw)


# ------------------------------------------------------- gait analysis recovers the truth


@pytest.mark.parametrize("fps", [30.0, 60.0])
@pytest.mark.parametrize("speed", [1.0, 1.5])
@pytest.mark.parametrize("dyaw_deg", [0.0, 45.0, -45.0, 90.0, -90.0])
def test_gait_cycles_recover_the_walkers_controls(
    fps: float, speed: float, dyaw_deg: float
) -> None:
    motion, truth = procedural_walk(speed=speed, dyaw_per_cycle=dyaw_deg * DEG, fps=fps, cycles=3)
    cycles = gait_cycles(motion)
    assert len(cycles) == truth.num_cycles
    for i, cy in enumerate(cycles):
        assert cy.foot == "left"
        # Contact onsets come from thresholds on sampled heights and speeds: ±2 frames.
        assert abs(cy.start - truth.strike_frames[i]) <= 2
        assert abs(cy.end - truth.strike_frames[i + 1]) <= 2
        # 3 cm / 2° / 3 %: what a model fitted on these parameters can tolerate; the walker's
        # root moves along a uniform arc, so a shifted window changes nothing in theory.
        assert abs(cy.dz - truth.dz[i]) <= 0.03
        assert abs(cy.dx - truth.dx[i]) <= 0.03
        assert abs(cy.dyaw - truth.dyaw[i]) <= 2 * DEG
        assert abs(cy.speed / truth.speed[i] - 1) <= 0.03
        assert cy.height == pytest.approx(truth.height, abs=1e-3)  # float32 offsets


@pytest.mark.parametrize("kw", WALKS)
def test_foot_contacts_match_the_walkers_stance(kw: dict) -> None:
    motion, truth = procedural_walk(**kw)
    fc = foot_contacts(motion)
    f = truth.strike_frames
    right = np.rint((truth.left_strikes[:-1] + 0.5 * truth.duration) * motion.fps).astype(int)
    for found, true in ((fc.left_strikes, f), (fc.right_strikes, right)):
        assert len(found) == len(true)
        assert np.abs(found - true).max() <= 2  # as above: threshold crossings, ±2 frames
    # Hysteresis lets a contact end a little late: most frames still agree with the truth.
    agree = np.mean(np.stack([fc.left, fc.right], -1) == truth.contacts)
    assert agree > 0.9


# ----------------------------------------------------------------------------- datasets


@pytest.fixture(scope="module")
def walker_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three walker clips (one in a sub-folder) written as BVH, plus a labels file."""
    root = tmp_path_factory.mktemp("walks")
    (root / "sub").mkdir()
    for name, kw in (
        ("b_turn.bvh", dict(dyaw_per_cycle=0.4, seed=1)),
        ("a_straight.bvh", dict(seed=2)),
        ("sub/c_fast.bvh", dict(speed=1.5, fps=30.0, seed=3)),
    ):
        write_bvh(root / name, procedural_walk(cycles=1, **kw)[0])
    (root / "labels.csv").write_text(
        "file,actor,style,repetition,notes\n"
        "a_straight.bvh,ann,normal,1,first\n"
        "\n"
        "sub/c_fast,bob,brisk,2,\n"
    )
    return root


def test_load_dataset_reads_sorted_clips_with_labels(walker_folder: Path) -> None:
    clips = load_dataset(walker_folder)
    assert all(isinstance(c, Clip) for c in clips)
    assert [Path(c.path).relative_to(walker_folder).as_posix() for c in clips] == [
        "a_straight.bvh",
        "b_turn.bvh",
        "sub/c_fast.bvh",
    ]
    assert [(c.actor, c.style, c.repetition) for c in clips] == [
        ("ann", "normal", 1),
        (None, None, None),  # not in the labels file
        ("bob", "brisk", 2),
    ]
    original, _ = procedural_walk(cycles=1, seed=2)
    a = clips[0]
    assert a.dropped_frames == 0  # a walk has no T-pose: nothing to drop
    assert a.motion.num_frames == original.num_frames and a.motion.fps == pytest.approx(60.0)
    # BVH keeps 6 decimals of degrees and metres: 1e-5 m after FK over ~1 m of bones.
    np.testing.assert_allclose(_world(a.motion)[0], _world(original)[0], atol=1e-5)
    assert clips[2].motion.fps == pytest.approx(30.0)


def test_labels_can_live_elsewhere_and_scale_is_passed_on(
    walker_folder: Path, tmp_path: Path
) -> None:
    labels = tmp_path / "my labels.csv"
    labels.write_text("File , Actor, STYLE, repetition\nb_turn,cy,turn,\n")
    clips = load_dataset(walker_folder, labels=labels, scale=0.5)
    assert [(c.actor, c.style, c.repetition) for c in clips] == [
        (None, None, None),
        ("cy", "turn", None),  # a blank repetition is unknown
        (None, None, None),
    ]
    metres, _ = rest_positions(load_dataset(walker_folder)[0].motion.skeleton)
    halved, _ = rest_positions(clips[0].motion.skeleton)
    np.testing.assert_allclose(halved, 0.5 * metres, atol=1e-6)


def test_sort_order_is_case_sensitive(tmp_path: Path) -> None:
    motion, _ = procedural_walk(cycles=1)
    for name in ("b.bvh", "B.bvh", "a.BVH"):
        write_bvh(tmp_path / name, motion)
    names = [Path(c.path).name for c in load_dataset(tmp_path)]
    assert names == ["B.bvh", "a.BVH", "b.bvh"]  # code-point order: upper case first


def _labels_error(folder: Path, text: str, tmp_path: Path) -> str:
    path = tmp_path / "labels.csv"
    path.write_text(text)
    with pytest.raises(DataError) as info:
        load_dataset(folder, labels=path)
    return str(info.value)


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("file,actor,repetition\na_straight,x,1\n", 1, "missing column 'style'"),
        ("", 1, "expected a header row"),
        (
            "file,actor,style,repetition\na_straight,x,y,1\nb_turn,x,y,two\n",
            3,
            "integer repetition, found 'two'",
        ),
        ("file,actor,style,repetition\n\nsub/missing,x,y,1\n", 3, "'sub/missing' does not exist"),
        ("file,actor,style,repetition\nc_fast,x,y,1\n", 2, "'c_fast' does not exist"),  # needs sub/
        (
            "file,actor,style,repetition\na_straight,x,y,1\nb_turn,x,y,1\na_straight.bvh,x,y,2\n",
            4,
            "duplicate row for 'a_straight.bvh' \\(first at line 2\\)",
        ),
        ("file,actor,style,repetition\na_straight,x,y,1_000\n", 2, "integer repetition"),
        ("file,actor,style,repetition\na_straight,x,y\n", 2, "expected 4 fields, found 3"),
    ],
)
def test_bad_labels_name_the_line(
    walker_folder: Path, tmp_path: Path, text: str, line: int, words: str
) -> None:
    message = _labels_error(walker_folder, text, tmp_path)
    assert re.search(re.escape(f"{tmp_path / 'labels.csv'}:{line}:") + ".*" + words, message), (
        message
    )


def test_missing_or_empty_folders_and_labels(tmp_path: Path) -> None:
    with pytest.raises(
        DataError, match=re.escape(f"{tmp_path / 'nope'}: expected a dataset folder")
    ):
        load_dataset(tmp_path / "nope")
    (tmp_path / "empty" / "deep").mkdir(parents=True)
    (tmp_path / "empty" / "deep" / "notes.txt").write_text("no clips here")
    with pytest.raises(DataError, match=re.escape(f"{tmp_path / 'empty'}: expected *.bvh files")):
        load_dataset(tmp_path / "empty")
    write_bvh(tmp_path / "one.bvh", procedural_walk(cycles=1)[0])
    with pytest.raises(
        DataError, match=re.escape(f"{tmp_path / 'gone.csv'}: expected a labels file")
    ):
        load_dataset(tmp_path, labels=tmp_path / "gone.csv")


def test_labels_that_are_not_text_are_a_data_error(walker_folder: Path, tmp_path: Path) -> None:
    path = tmp_path / "labels.csv"
    path.write_bytes(b"file,actor,style,repetition\n\xff\xfe,x,y,1\n")
    with pytest.raises(DataError, match=re.escape(str(path)) + ": expected UTF-8"):
        load_dataset(walker_folder, labels=path)


def test_a_broken_bvh_error_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    with pytest.raises(BVHError, match=re.escape(str(tmp_path / "bad.bvh"))):
        load_dataset(tmp_path)


def test_cmu_walks_load_without_their_tpose(cmu_dir: Path) -> None:
    clips = load_dataset(cmu_dir / "walk")
    assert len(clips) == 26
    names = [Path(c.path).stem for c in clips]
    assert names == sorted(names)
    with open(cmu_dir / "index.csv", newline="") as f:
        index = {Path(r["file"]).stem: r for r in csv.DictReader(f)}
    for clip, name in zip(clips, names, strict=True):
        # Every file starts with the conversion's T-pose; 07_12 also has an empty frame 1.
        assert clip.dropped_frames == (2 if name == "07_12" else 1), name
        assert clip.dropped_frames == int(index[name]["first_motion_frame"]), name
        assert clip.motion.num_frames == int(index[name]["frames"]) - clip.dropped_frames
        assert (clip.actor, clip.style, clip.repetition) == (None, None, None)
        assert clip.motion.skeleton.num_joints == 31
