"""MotionModel files: save → load rebuilds the same model (same predictions, same bytes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import fully_optimised

from jcrowd.errors import StoreError
from jcrowd.io import load_motion_model, save_motion_model, save_tensor_model
from jcrowd.model import TensorModel, fit_motion_model, level_pose_vectors


def test_round_trip(cmu16_tensor: TensorModel, tmp_path: Path) -> None:
    # The run's shared cmu16 tensor fit (conftest), kriged here: the format does not depend on
    # how the levels were fitted, and a fit of its own would cost this test most of a minute.
    tensor = cmu16_tensor
    with fully_optimised():
        model = fit_motion_model(tensor)
    path = tmp_path / "m.jcm"
    save_motion_model(path, model, extra={"note": "test"})
    back, extra = load_motion_model(path)
    assert extra == {"note": "test"}
    assert back.control_names == model.control_names and back.fps == model.fps
    c = np.array([[0.2, 1.1, 0.5], [0.0, 1.4, -0.3]])
    for level in range(len(model.levels)):
        np.testing.assert_array_equal(
            level_pose_vectors(back, c, level), level_pose_vectors(model, c, level)
        )
    save_motion_model(tmp_path / "again.jcm", back, extra=extra)
    assert (tmp_path / "again.jcm").read_bytes() == path.read_bytes()
    save_tensor_model(tmp_path / "t.jcm", tensor)
    with pytest.raises(StoreError, match="expected a 'motion-model' file"):
        load_motion_model(tmp_path / "t.jcm")
