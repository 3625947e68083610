"""Regenerate the renderer's golden images ``tests/golden/*.png``.

The scenes live in ``tests/test_render_golden.py`` (the tests only compare against these files,
never write them). Run from the repository root after an intended change to the renderer's
look, then open the PNGs and check them before committing: ``python scripts/make_golden.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_render_golden import GOLDEN, SCENES, render_scene  # noqa: E402

from jcrowd.render import gl_renderer, make_context, write_png  # noqa: E402


def main() -> None:
    GOLDEN.mkdir(parents=True, exist_ok=True)
    ctx = make_context()
    try:
        for name, make in SCENES.items():
            path = GOLDEN / f"{name}.png"
            write_png(path, render_scene(ctx, make()))
            print(f"wrote {path.relative_to(ROOT)}")
        print(f"renderer: {gl_renderer(ctx)}")
    finally:
        ctx.release()


if __name__ == "__main__":
    main()
