"""What every bench script shares: where the data is, the machine's name, and RESULTS.md rows.

The bench scripts are run as files (``python bench/NAME.py``), so they import this module from
their own folder.
"""

from __future__ import annotations

import datetime as dt
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "RESULTS.md"


def data_root() -> Path:
    """The folder holding ``cmu/`` and ``cmu16/``: ``$JCROWD_DATA`` (or its parent when it names
    ``cmu/`` itself), else ``../shared/data`` beside the checkout."""
    env = os.environ.get("JCROWD_DATA")
    base = Path(env) if env else ROOT.parent / "shared" / "data"
    return base if (base / "cmu").is_dir() else base.parent


def machine() -> str:
    return f"{platform.node()} {platform.machine()} {os.cpu_count()} cpu"


def code_version() -> str:
    """The checkout's commit, marked ``+dirty`` when jcrowd/ or bench/ differ from it."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "jcrowd", "bench/*.py"],
            cwd=ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
    except OSError:
        return "unknown"
    return (head or "unknown") + ("+dirty" if dirty else "")


def append_result(name: str, details: str, body: str) -> None:
    """Append a dated section ``## name — date — code … — details`` with ``body`` to RESULTS.md."""
    if not RESULTS.exists():
        RESULTS.write_text("# Benchmark results\n\nOne dated row per run; newest last.\n")
    head = f"## {name} — {dt.date.today().isoformat()} — code {code_version()} — {details}"
    with RESULTS.open("a") as f:
        f.write(f"\n{head}\n\n{body.rstrip()}\n")
    print(f"appended to {RESULTS}", file=sys.stderr)


def report(name: str, details: str, out: dict, text: str, as_json: bool, record: bool) -> None:
    """Print ``out`` as one JSON object (``--json``) or ``text``; append ``text`` to RESULTS.md."""
    import json

    if as_json:
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
    else:
        print(text)
    if record:
        append_result(name, details, text)
