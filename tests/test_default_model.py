"""The shipped default model loads without any data folder and walks corners."""

from __future__ import annotations

import numpy as np

import jcrowd
from jcrowd.io import default_model_path
from jcrowd.model import synthesize_clip


def test_default_model_loads_and_turns() -> None:
    assert default_model_path().stat().st_size <= 5 * 1024 * 1024  # ships inside the package
    model = jcrowd.load_default_model()
    assert model.control_names == ("dx", "dz", "dyaw")
    lo, hi = np.asarray(model.control_ranges)[2]
    # Heading changes of at least ±60° per cycle are inside the fitted range.
    assert lo <= -np.radians(60) and hi >= np.radians(60)
    for dyaw in (-1.0, 1.0):  # ±57°: a corner walked over one cycle
        clip = synthesize_clip(model, [0.3 * np.sign(dyaw), 0.9, dyaw], 0)
        end = np.asarray(clip.root_positions)[-1]
        assert np.sign(end[0]) == np.sign(dyaw)  # turning left ends to the left (+x)
        assert clip.num_frames > 30
