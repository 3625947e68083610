"""Measured pedestrian trajectories: the HERMES corridor runs (the shared data's ``hermes_uo``).

A run file holds one row per person and frame, ``id frame x y [z]`` separated by whitespace,
``#`` lines being comments. For HERMES the units and the frame rate are not in the file; the
data's README gives them (centimetres, 16 fps) and the file name gives the geometry:
``uo-<entrance>-<corridor>-<exit>``, the three widths in centimetres. Beside the runs,
``steady_state.csv`` (``run,first_frame,last_frame``) names each run's steady-state frames.
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jcrowd.errors import DataError

__all__ = ["HERMES_FPS", "MeasuredRun", "load_hermes_run", "load_hermes_runs"]

HERMES_FPS = 16.0
"""Frames per second of the HERMES recordings (data README; not in the files)."""

_NAME = re.compile(r"uo-(\d+)-(\d+)-(\d+)$")


@dataclass(frozen=True)
class MeasuredRun:
    """One measured run, in metres and frames.

    Attributes:
        name: the file's stem, e.g. ``uo-180-180-120``.
        rows: ``(R, 4)`` ``id, frame, x, y`` (m; people walk towards −y).
        fps: frames per second.
        entrance_m, corridor_m, exit_m: the widths the name gives (m).
        steady: the steady-state frames ``(first, last)``, ``None`` if ``steady_state.csv``
            does not list the run.
    """

    name: str
    rows: np.ndarray
    fps: float
    entrance_m: float
    corridor_m: float
    exit_m: float
    steady: tuple[int, int] | None


def _steady(folder: Path) -> dict[str, tuple[int, int]]:
    path = folder / "steady_state.csv"
    if not path.exists():
        return {}
    out: dict[str, tuple[int, int]] = {}
    with path.open(newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                out[row["run"]] = (int(row["first_frame"]), int(row["last_frame"]))
            except (KeyError, TypeError, ValueError) as e:
                raise DataError(
                    f"{path}:{line}: expected 'run,first_frame,last_frame' with integer frames, "
                    f"found {row}"
                ) from e
    return out


def load_hermes_run(path: str | os.PathLike[str]) -> MeasuredRun:
    """Read one HERMES run (centimetres → metres) and its steady-state frames.

    Raises:
        DataError: a name not of the form ``uo-<entrance>-<corridor>-<exit>``, a row that is
            not ``id frame x y [z]`` numbers, or a file with no rows (``path:line``).
    """
    p = Path(path)
    m = _NAME.match(p.stem)
    if m is None:
        raise DataError(
            f"{p}: expected a HERMES run named uo-<entrance>-<corridor>-<exit> (widths in cm), "
            f"found the name {p.stem!r}"
        )
    if not p.is_file():
        raise DataError(f"{p}: expected a trajectory file, found none")
    rows: list[list[float]] = []
    with p.open() as f:
        for line, text in enumerate(f, start=1):
            text = text.strip()
            if not text or text.startswith("#"):
                continue
            parts = text.split()
            try:
                values = [float(v) for v in parts[:4]]
            except ValueError:
                values = []
            if len(values) != 4 or len(parts) > 5 or not all(np.isfinite(values)):
                raise DataError(f"{p}:{line}: expected 'id frame x y [z]' numbers, found {text!r}")
            rows.append(values)
    if not rows:
        raise DataError(f"{p}: expected rows 'id frame x y [z]', found none")
    table = np.asarray(rows, np.float64)
    table[:, 2:4] /= 100.0
    entrance, corridor, exit_ = (int(g) / 100.0 for g in m.groups())
    return MeasuredRun(
        p.stem, table, HERMES_FPS, entrance, corridor, exit_, _steady(p.parent).get(p.stem)
    )


def load_hermes_runs(paths: list[str | os.PathLike[str]]) -> list[MeasuredRun]:
    """Every run named by ``paths``: files, or folders whose ``uo-*.txt`` files are read."""
    files: list[Path] = []
    for path in paths:
        p = Path(path)
        if p.is_dir():
            found = sorted(p.glob("uo-*.txt"))
            if not found:
                raise DataError(f"{p}: expected HERMES runs uo-*.txt in the folder, found none")
            files.extend(found)
        else:
            files.append(p)
    return [load_hermes_run(f) for f in files]
