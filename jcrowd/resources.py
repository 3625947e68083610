"""Files shipped inside the package (found with :mod:`importlib.resources`, so they work from
an installed wheel as well as a source tree)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["sample_bvh_path"]


def _asset(name: str) -> Path:
    return Path(str(resources.files("jcrowd") / "assets" / name))


def sample_bvh_path() -> Path:
    """A short walk (three gait cycles, turning gently left) made by the procedural walker.

    Rebuilt by ``python scripts/make_sample.py``; used by ``jcrowd inspect`` with no file.
    """
    return _asset("sample_walk.bvh")
