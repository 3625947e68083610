"""Rebuild ``jcrowd/assets/sample_walk.bvh``, the clip ``jcrowd inspect`` shows with no file.

Three gait cycles of the procedural walker at 1.3 m/s turning 0.15 rad (8.6°) left per cycle,
60 fps, in metres. Run from the repository root: ``python scripts/make_sample.py``.
"""

from __future__ import annotations

from pathlib import Path

from jcrowd.io import write_bvh
from jcrowd.motion import procedural_walk

TARGET = Path(__file__).resolve().parents[1] / "jcrowd" / "assets" / "sample_walk.bvh"


def main() -> None:
    motion, _ = procedural_walk(cycles=3, speed=1.3, dyaw_per_cycle=0.15, fps=60.0, seed=0)
    write_bvh(TARGET, motion, precision=5)
    print(f"wrote {TARGET} ({TARGET.stat().st_size / 1024:.0f} KiB, {motion.num_frames} frames)")


if __name__ == "__main__":
    main()
