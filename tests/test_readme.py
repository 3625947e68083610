"""README and docs/ cannot rot: their commands and Python blocks run here, their links resolve.

Blocks are found by the marker line right above them, never by position:

- ``<!-- main-command -->`` and ``<!-- test-command -->``: the two install lines. CI runs the
  test line itself (``.ci/run`` reads the line two below its marker); a fresh-machine check runs
  the demo line (``jcrowd demo`` itself is tested in test_cli_crowd.py).
- ``<!-- tour -->``: the README's tour, run line by line in one temporary folder.
- ``<!-- check: NAME -->``: a Python block, executed; the check ``NAME`` below then asserts on
  the names the block defined (a block without a check fails).

Every ``bash`` block of a docs page runs line by line in one temporary folder per page (so later
commands find earlier outputs), with ``../shared/data`` pointed at the data folder and
``examples/`` at the repository's. ``text`` blocks (long runs: calibration, layout optimisation,
several processes) are shown, not run; their tests run the same commands on small inputs.
Figures name their ``bench/RESULTS.md`` row as ``row "BENCH — DATE … PART OF THE HEADING"``;
every such row must exist there.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import fully_optimised

ROOT = Path(__file__).resolve().parents[1]
PAGES = {"README.md": ROOT / "README.md"} | {
    f"docs/{p.name}": p for p in sorted((ROOT / "docs").glob("*.md"))
}


def _blocks(lang: str, page: str = "README.md") -> list[str]:
    return re.findall(rf"```{lang}\n(.+?)\n```", PAGES[page].read_text(), flags=re.S)


def _tagged(page: str) -> dict[str, tuple[str, str]]:
    """``marker -> (language, body)`` of every block whose fence follows a marker line."""
    found = re.findall(
        r"^<!-- ([\w: -]+?) -->\n```(\w+)\n(.+?)\n```", PAGES[page].read_text(), flags=re.S | re.M
    )
    return {marker: (lang, body) for marker, lang, body in found}


def _block_after(marker: str, page: str = "README.md") -> str:
    tagged = _tagged(page)
    if marker not in tagged:
        pytest.fail(f"{page}: no code block right after '<!-- {marker} -->'")
    return tagged[marker][1]


# A fit runs a few programs over every frame of every capture (the per-level refit), so it
# takes less time compiled with XLA's full optimisation than with the tests' cheaper compile
# (conftest): these commands and blocks run that way (``helpers.fully_optimised``).
FITS = ("jcrowd fit ",)
FIT_BLOCKS = {"tensor"}

# A block's call that is exactly a session fixture's (the same function, data and defaults) takes
# the fixture's value, so the run fits cmu16 once: the block's name -> (its call, the fixture).
# The rest of the block runs as written; a block whose call changes fails here until this follows.
SHARED_CALLS = {"tensor": ('build_tensor_model(load_dataset("{data}/cmu16"))', "cmu16_tensor")}


def _run_commands(commands: list[str], data: Path, cwd: Path) -> None:
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    for command in commands:
        full = {"JAX_DISABLE_MOST_OPTIMIZATIONS": "0"} if command.startswith(FITS) else {}
        proc = subprocess.run(
            _localise(command, data),
            shell=True,
            cwd=cwd,
            env=env | full,
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
        assert proc.returncode == 0, f"{command}\n{proc.stderr[-2000:]}"


def _localise(line: str, data: Path) -> str:
    line = line.replace("../shared/data", str(data))
    return re.sub(r"(?<![\w/])examples/", str(ROOT / "examples") + "/", line)


def test_ci_finds_the_two_commands() -> None:
    """``.ci/run`` takes the line two below ``<!-- test-command -->``: it must be the test line."""
    lines = PAGES["README.md"].read_text().splitlines()
    for marker, tail in (("main-command", "jcrowd demo"), ("test-command", "pytest -q -n auto")):
        at = lines.index(f"<!-- {marker} -->")
        assert lines[at + 1] == "```bash"
        assert lines[at + 2].startswith("python3 -m venv .venv && ")
        assert lines[at + 2].endswith(tail)
        assert _block_after(marker) == lines[at + 2]


# The tour and the docs pages are sequences of whole commands (a full fit with the per-level
# refit, a run, a render, exports), each several times the 300 s budget of one unit test's
# share on a loaded 2-core machine: measured over 300 s with the machine under the suite's
# load. Their own limit is the commands' sum.
@pytest.mark.slow
@pytest.mark.timeout(900)
def test_every_command_in_the_guide_runs(cmu16_dir: Path, tmp_path: Path) -> None:
    data = cmu16_dir.parent
    commands = [c for c in _block_after("tour").splitlines() if c.strip()]
    assert any(c.startswith("jcrowd export") for c in commands)  # the tour reaches the end
    _run_commands(commands, data, tmp_path)
    assert (tmp_path / "plaza.mp4").stat().st_size > 0
    assert (tmp_path / "agents" / "agent_42.bvh").exists()


_DOC_PAGES = [page for page in PAGES if page != "README.md" and _blocks("bash", page)]


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("page", _DOC_PAGES)
def test_every_command_in_the_docs_runs(page: str, cmu16_dir: Path, tmp_path: Path) -> None:
    commands = [c for block in _blocks("bash", page) for c in block.splitlines() if c.strip()]
    _run_commands(commands, cmu16_dir.parent, tmp_path)


def test_the_docs_have_commands_to_run() -> None:
    """The docs pages' commands are collected (a renamed folder would silently run none)."""
    assert "docs/fit.md" in _DOC_PAGES


def _check_api(ns: dict[str, Any]) -> None:
    """README: a turning clip, and the plaza's state and frame after the loop."""
    clip = ns["clip"]
    assert clip.rotations.shape == (clip.num_frames, clip.skeleton.num_joints, 4)
    walked = np.asarray(clip.root_positions[-1] - clip.root_positions[0])
    assert walked[2] > 0.5  # dz = 1.3 m asked: the cycle walks forward
    sim, state, frame = ns["sim"], ns["state"], ns["frame"]
    n = sim.num_agents
    assert state.x.shape == state.z.shape == (n,)
    assert np.isfinite(np.asarray(state.x)).all()
    level = np.asarray(frame.level)
    assert level.shape == (n,)
    assert ((level >= 0) & (level <= len(frame.points))).all()  # len(points): not synthesized
    assert len(frame.slots) == len(frame.valid) == len(frame.points)
    for slots, valid, points in zip(frame.slots, frame.valid, frame.points, strict=True):
        assert points.ndim == 3 and points.shape[0] == slots.shape[0] and points.shape[2] == 3
        assert np.isfinite(np.asarray(points)[np.asarray(valid)]).all()
    assert sum(int(np.asarray(v).sum()) for v in frame.valid) > 0  # someone drawn with limbs


def _check_tensor(ns: dict[str, Any]) -> None:
    """docs/fit.md: the saved and re-read tensor model reconstructs the samples."""
    joint_m, root_m = ns["level_errors"](ns["model"], 0)
    # level 0 of cmu16 reconstructs to 0.51 cm (row "tensor — 2026-12-04"); 1 cm leaves room
    # for a refit on another BLAS, while a broken load or level is off by tens of cm
    assert 0.0 < joint_m < 0.01 and root_m < 0.02


def _check_footprints(ns: dict[str, Any]) -> None:
    """docs/fit.md: three cycles solved, each foot closer than the forward rule puts it."""
    sol, model = ns["sol"], ns["model"]
    assert sol.controls.shape == (3, len(model.control_names))
    assert np.isfinite(np.asarray(sol.controls)).all()
    error, forward = np.asarray(sol.error_m), np.asarray(sol.forward_error_m)
    assert error.shape == forward.shape == (3,)
    assert np.all(error <= forward + 1e-6)  # the solve starts from the forward rule's controls
    assert np.all(error < 0.10)  # a few cm on these footprints; a failed solve misses by decimetres


CHECKS: dict[str, Callable[[dict[str, Any]], None]] = {
    "api": _check_api,
    "tensor": _check_tensor,
    "footprints": _check_footprints,
}

_PY_BLOCKS = [
    (page, marker.removeprefix("check: "))
    for page in PAGES
    for marker, (lang, _) in _tagged(page).items()
    if lang == "python" and marker.startswith("check: ")
]


def test_every_python_block_has_a_check() -> None:
    for page in PAGES:
        tagged = [m for m, (lang, _) in _tagged(page).items() if lang == "python"]
        assert len(tagged) == len(_blocks("python", page)), f"{page}: an untagged Python block"
        assert all(m.startswith("check: ") and m[7:] in CHECKS for m in tagged), (page, tagged)
    assert ("README.md", "api") in _PY_BLOCKS


@pytest.mark.slow
@pytest.mark.parametrize(("page", "name"), _PY_BLOCKS, ids=[f"{p}-{n}" for p, n in _PY_BLOCKS])
def test_every_python_block_runs(
    page: str,
    name: str,
    cmu_dir: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    request: pytest.FixtureRequest,
) -> None:
    code = _localise(_block_after(f"check: {name}", page), cmu_dir.parent)
    monkeypatch.chdir(tmp_path)
    code = code.replace("for i in range(sim.steps):", "for i in range(30):")  # keep it quick
    namespace: dict[str, Any] = {"__name__": "readme"}
    if name in SHARED_CALLS:
        call, fixture = SHARED_CALLS[name]
        call = call.format(data=cmu_dir.parent)
        assert call in code, f"{page} block {name}: no '{call}' (update SHARED_CALLS)"
        namespace["_shared_value"] = request.getfixturevalue(fixture)
        code = code.replace(call, "_shared_value")
    with fully_optimised() if name in FIT_BLOCKS else contextlib.nullcontext():
        exec(compile(code, f"{page} python block {name}", "exec"), namespace)
    CHECKS[name](namespace)


def _links(text: str) -> list[str]:
    targets = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'src="([^"]+)"', text)
    return [t.split("#")[0] for t in targets if not re.match(r"[a-z]+:|#", t)]


@pytest.mark.parametrize("page", list(PAGES))
def test_every_linked_file_exists(page: str) -> None:
    here = PAGES[page].parent
    missing = [t for t in _links(PAGES[page].read_text()) if not (here / t).exists()]
    assert not missing, f"{page} links to missing files: {missing}"


_HEADINGS = [
    h for h in (ROOT / "bench" / "RESULTS.md").read_text().splitlines() if h.startswith("## ")
]


@pytest.mark.parametrize("page", list(PAGES))
def test_every_cited_row_is_in_the_results(page: str) -> None:
    text = " ".join(PAGES[page].read_text().split())
    for cited in re.findall(r'\brows? "([^"]+)"', text):
        name, _, rest = cited.partition(" — ")
        date, _, part = rest.partition(" … ")
        assert any(h.startswith(f"## {name} — {date}") and part in h for h in _HEADINGS), (
            f'{page}: row "{cited}" is not a heading of bench/RESULTS.md'
        )


@pytest.mark.parametrize("page", list(PAGES))
def test_the_pages_describe_today(page: str) -> None:
    """History (what the code used to do, commit hashes) lives in git log and bench/RESULTS.md."""
    history = re.compile(r"used to|no longer|before the|has since|tried|code [0-9a-f]{7}")
    found = [ln for ln in PAGES[page].read_text().splitlines() if history.search(ln)]
    assert not found, f"{page}: {found}"
