"""Rebuild ``jcrowd/assets/default_model.jcm``, the motion model shipped inside the package.

Fitted from the CMU subject-16 walks (``../shared/data/cmu16``: straight walks, veers and
90-degree turns, so a crowd can walk paths with corners), mirrored, with the default settings
of ``jcrowd fit``. Anyone with the data can run it from the repository root:

    python scripts/make_default_model.py [--data ../shared/data/cmu16]

The data used in this project was obtained from mocap.cs.cmu.edu.
The database was created with funding from NSF EIA-0196217.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jcrowd.cli import main as jcrowd_main

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "cmu16"))
    args = ap.parse_args()
    target = ROOT / "jcrowd" / "assets" / "default_model.jcm"
    raise SystemExit(jcrowd_main(["fit", args.data, "--out", str(target), "--no-cv"]))


if __name__ == "__main__":
    main()
