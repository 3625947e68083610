"""README cannot rot: every shell command and Python block in it runs here.

The two install lines at the top are run by CI itself (the test line) and by a fresh-machine
check (the demo line; `jcrowd demo` itself is tested in test_cli_crowd.py). Every later ``bash``
block runs line by line in one temporary folder (so later commands find earlier outputs), with
``../shared/data`` pointed at the data folder and ``examples/`` at the repository's.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT = (ROOT / "README.md").read_text()


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.+?)\n```", TEXT, flags=re.S)


def _localise(line: str, data: Path) -> str:
    line = line.replace("../shared/data", str(data))
    return re.sub(r"(?<![\w/])examples/", str(ROOT / "examples") + "/", line)


def test_every_command_in_the_guide_runs(cmu16_dir: Path, tmp_path: Path) -> None:
    data = cmu16_dir.parent
    commands = [c for block in _blocks("bash")[2:] for c in block.splitlines() if c.strip()]
    assert any(c.startswith("jcrowd export") for c in commands)  # the tour reaches the end
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    for command in commands:
        proc = subprocess.run(
            _localise(command, data),
            shell=True,
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
        assert proc.returncode == 0, f"{command}\n{proc.stderr[-2000:]}"
    assert (tmp_path / "plaza.mp4").stat().st_size > 0
    assert (tmp_path / "agents" / "agent_42.bvh").exists()


@pytest.mark.parametrize("index", range(len(_blocks("python"))))
def test_every_python_block_runs(
    index: int, cmu_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    code = _localise(_blocks("python")[index], cmu_dir.parent)
    monkeypatch.chdir(tmp_path)
    code = code.replace("for i in range(sim.steps):", "for i in range(30):")  # keep it quick
    exec(compile(code, f"README.md python block {index}", "exec"), {"__name__": "readme"})
