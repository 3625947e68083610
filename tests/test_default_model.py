"""The shipped default model loads without any data folder and walks corners."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_default_model_metadata_names_no_path_of_this_machine(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`jcrowd inspect` of the shipped model holds no absolute path (the model was fitted on a
    developer's machine): the dataset is named by its folder and its clips' checksums
    (issue 21). A string is a path of a machine when it starts with "/" or a drive letter."""
    import json
    import re

    from jcrowd.cli import main

    # As the issue runs it: from the repository root, with the relative path (inspect echoes
    # the path it is given as "file").
    root = default_model_path().parents[2]
    monkeypatch.chdir(root)
    assert main(["inspect", "jcrowd/assets/default_model.jcm", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)

    def strings(x: object):  # type: ignore[no-untyped-def]
        if isinstance(x, str):
            yield x
        elif isinstance(x, dict):
            for k, v in x.items():
                yield k
                yield from strings(v)
        elif isinstance(x, list):
            for v in x:
                yield from strings(v)

    absolute = [s for s in strings(report) if re.match(r"^(/|[A-Za-z]:[\\\\/])", s)]
    assert absolute == []
    fit = report["fit"]
    assert fit["dataset"] == "cmu16" and len(fit["clip_sha256"]) == fit["clips"]
