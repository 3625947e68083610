"""The command line: --version, inspect (human and JSON), errors, and the README's commands."""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import fully_optimised

from jcrowd import __version__
from jcrowd.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, dict]:
    code = main(argv)
    out = capsys.readouterr().out
    return code, json.loads(out)


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"jcrowd {__version__}"


def test_inspect_07_01_json(cmu_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, result = _json(capsys, ["inspect", str(cmu_dir / "walk" / "07_01.bvh"), "--json"])
    assert code == 0
    # The acceptance facts for this clip.
    assert result["joints"] == 31
    assert result["fps"] == pytest.approx(120.0, abs=1e-3)
    assert result["frames"] == 316
    assert result["dropped_frames"] == 1
    assert result["units"] == "cmu"
    cycles = result["gait_cycles"]
    assert len(cycles) >= 2
    assert all(0.8 <= c["dz"] <= 2.0 for c in cycles)
    for key in ("start", "end", "dx", "dz", "dyaw", "speed"):
        assert all(key in c for c in cycles)
    assert result["duration_s"] == pytest.approx(316 / 120, abs=1e-6)
    assert len(result["bone_lengths_m"]) == 31
    assert result["contacts"]["feet"]["left"] == ["LeftFoot", "LeftToeBase"]


def test_inspect_second_skeleton_json(cmu16_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, result = _json(capsys, ["inspect", str(cmu16_dir / "16_17.bvh"), "--json"])
    assert code == 0
    assert (result["joints"], result["frames"], result["dropped_frames"]) == (19, 129, 0)
    assert result["fps"] == pytest.approx(30.0, abs=1e-3)
    assert result["units"] == "cm"
    assert max(abs(c["dyaw_deg"]) for c in result["gait_cycles"]) > 60


def test_inspect_human_output(cmu_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(cmu_dir / "walk" / "07_01.bvh")]) == 0
    out = capsys.readouterr().out
    assert "31 joints, 316 frames at 120 fps" in out
    assert "gait cycles" in out


def test_inspect_shipped_sample(capsys: pytest.CaptureFixture[str]) -> None:
    code, result = _json(capsys, ["inspect", "--json"])
    assert code == 0
    assert result["file"].endswith("sample_walk.bvh")
    # The sample is the procedural walker: three left-started cycles, gently turning left.
    left = [c for c in result["gait_cycles"] if c["foot"] == "left"]
    assert len(left) == 3
    assert all(c["dyaw"] > 0 for c in left)


def test_inspect_errors_are_one_json_object(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    code, result = _json(capsys, ["inspect", str(bad), "--json"])
    assert code == 2
    assert result["error"]["type"] == "BVHError"
    assert "bad.bvh" in result["error"]["message"]
    code = main(["inspect", str(tmp_path / "missing.bvh")])
    assert code == 2
    assert "missing.bvh" in capsys.readouterr().err


def test_console_script_runs() -> None:
    # The installed entry point (what README's first line runs), in a separate process.
    proc = subprocess.run(
        [sys.executable, "-m", "jcrowd.cli", "inspect", "--json"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["joints"] > 10
    assert "shipped sample" in proc.stderr  # logs go to stderr, JSON alone to stdout


def test_readme_starts_with_the_two_commands() -> None:
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.+?)\n```", text)
    main_cmd, test_cmd = blocks[0], blocks[1]
    assert text.index(main_cmd) < 400, "the two commands open the README"
    assert "pip install ." in main_cmd and main_cmd.rstrip().endswith(
        ("jcrowd inspect", "jcrowd demo")
    )
    assert "pip install -e '.[dev]'" in test_cmd and "pytest" in test_cmd
    # .ci/run reads the test command from the line after this marker.
    assert "<!-- test-command -->\n```bash\n" + test_cmd in text


def test_simplify_writes_levels_that_load_elsewhere(
    cmu16_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from bvh import Bvh

    from jcrowd.io import read_bvh

    out = tmp_path / "levels"
    code, report = _json(
        capsys,
        [
            "simplify",
            str(cmu16_dir / "16_15.bvh"),
            "--levels",
            "4",
            "--out-dir",
            str(out),
            "--json",
        ],
    )
    assert code == 0
    levels = report["levels"]
    assert [lv["joints"] for lv in levels] == sorted({lv["joints"] for lv in levels}, reverse=True)
    assert len(levels) == 4 and levels[0]["joints"] == 19
    assert levels[0]["mean_error_m"] == 0.0
    for key in ("joints", "mean_error_m", "max_error_m", "bone_length_variation_pct"):
        assert all(key in lv for lv in levels)
    assert all(lv["bone_length_variation_pct"] < 1.0 for lv in levels)
    assert report["seconds"] > 0
    assert (out / "report.json").is_file() and (out / "report.txt").is_file()
    for lv in levels:
        path = Path(lv["file"])
        assert read_bvh(path).skeleton.num_joints == lv["joints"]
        with open(path) as f:  # an independent parser sees the same skeleton
            assert len(Bvh(f.read()).get_joints_names()) == lv["joints"]


def test_simplify_rejects_too_many_levels(
    cmu16_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["simplify", str(cmu16_dir / "16_15.bvh"), "--levels", "40", "--out-dir", str(tmp_path)]
    code, result = _json(capsys, [*argv, "--json"])
    assert code == 2
    assert "at most 18 levels" in result["error"]["message"]


@pytest.mark.slow
@pytest.mark.timeout(600)  # a whole fit with cross-validation and report: ~90 s alone, 300+ loaded
def test_fit_writes_a_model_and_a_report(
    cmu16_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from jcrowd.io import load_motion_model

    out, report = tmp_path / "m.jcm", tmp_path / "report"
    argv = ["fit", str(cmu16_dir), "--levels", "3", "--out", str(out), "--report", str(report)]
    with fully_optimised():  # a fit runs long programs: XLA's full optimisation pays
        code, result = _json(capsys, [*argv, "--json"])
    assert code == 0
    for key in (
        "samples",
        "levels",
        "bytes_total",
        "bytes_raw",
        "variogram",
        "cv",
        "cv_root",
        "cv_z_rms",
        "seconds",
    ):
        assert key in result
    assert len(result["levels"]) == 3
    assert {"ranks", "joints", "bytes", "error_m"} <= set(result["levels"][0])
    assert set(result["cv"]) == {"kriging_m", "per_pose_m", "rbf_m", "nearest_m"}
    # On cmu16 (the second skeleton) kriging beats RBF and nearest (issue 6's bar).
    assert result["cv"]["kriging_m"] <= result["cv"]["rbf_m"] < result["cv"]["nearest_m"]
    assert 0.5 < result["cv_z_rms"] < 2.0  # the predicted std is the error's scale (0.78 measured)
    model, extra = load_motion_model(out)
    assert (
        model.control_names == ("dx", "dz", "dyaw") and extra["fit"]["samples"] == result["samples"]
    )
    # The file names its data by the folder's name and the clips' checksums, not by a path of
    # this machine (issue 21).
    fit = extra["fit"]
    assert fit["dataset"] == cmu16_dir.name and "data_dir" not in fit
    assert len(fit["clip_sha256"]) == result["clips"] and fit["out"] == "m.jcm"
    assert str(tmp_path) not in json.dumps(extra) and str(cmu16_dir) not in json.dumps(extra)
    some = sorted(fit["clip_sha256"])[0]
    assert fit["clip_sha256"][some] == hashlib.sha256((cmu16_dir / some).read_bytes()).hexdigest()
    assert {p.name for p in report.iterdir()} == {
        "report.txt",
        "levels.png",
        "reliability.png",
        "variogram.png",
    }
