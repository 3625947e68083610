"""Gait-cycle samples of a dataset: mirroring, groups, controls, the reference skeleton."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jcrowd.errors import DataError
from jcrowd.io import load_dataset
from jcrowd.model import CONTROL_NAMES, gait_samples, reference_skeleton
from jcrowd.motion import character_height, headings


@pytest.fixture(scope="module")
def cmu16_samples(cmu16_dir: Path) -> list:
    return gait_samples(load_dataset(cmu16_dir))


def test_samples_are_normalised_cycles_at_the_model_rate(cmu16_samples: list) -> None:
    assert len(cmu16_samples) > 40
    for s in cmu16_samples:
        assert s.motion.fps == 60.0
        assert s.motion.num_frames == s.cycle.end - s.cycle.start + 1
        root = np.asarray(s.motion.root_positions)
        assert np.abs(root[0, [0, 2]]).max() < 1e-5  # starts above the origin
        assert abs(float(headings(s.motion)[0])) < 1e-5  # facing +Z
        # The cut-out cycle moves by the cycle's own displacement (start heading frame).
        assert root[-1, 2] == pytest.approx(s.cycle.dz, abs=1e-4)
        assert root[-1, 0] == pytest.approx(s.cycle.dx, abs=1e-4)


def test_mirroring_doubles_and_balances_turns(cmu16_dir: Path, cmu16_samples: list) -> None:
    plain = gait_samples(load_dataset(cmu16_dir), mirrored=False)
    mirrored = [s for s in cmu16_samples if s.mirrored]
    assert len(cmu16_samples) == len(plain) + len(mirrored)
    assert not any(s.mirrored for s in plain)
    # Every mirrored sample's group is a clip that also has samples (same take).
    assert {s.group for s in mirrored} <= {s.group for s in cmu16_samples}
    yaw = np.array([s.cycle.dyaw for s in cmu16_samples])
    # Mirrored cycles are the original right-started cycles reflected: both turn directions.
    assert yaw.max() > np.radians(60) and yaw.min() < -np.radians(60)


def test_controls_and_reference_skeleton(cmu16_samples: list) -> None:
    c = np.array([s.controls() for s in cmu16_samples])
    assert c.shape == (len(cmu16_samples), len(CONTROL_NAMES))
    assert np.allclose(c[:, 4], c[0, 4])  # one subject
    np.testing.assert_array_equal(cmu16_samples[0].controls(("dyaw", "dx")), c[0, [2, 0]])
    with pytest.raises(DataError, match="expected names from"):
        cmu16_samples[0].controls(("speedy",))
    ref = reference_skeleton(cmu16_samples)
    assert character_height(ref) == pytest.approx(1.0, abs=1e-5)  # offsets ÷ height


def test_mixed_skeletons_are_rejected(cmu_dir: Path, cmu16_dir: Path) -> None:
    clips = load_dataset(cmu_dir / "walk")[:1] + load_dataset(cmu16_dir)[:1]
    with pytest.raises(DataError, match="expected the dataset's skeleton"):
        gait_samples(clips)
    with pytest.raises(DataError, match="at least one clip"):
        gait_samples([])
