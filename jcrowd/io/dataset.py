"""Datasets: a folder of BVH clips with optional labels, and the built-in procedural walker.

A dataset is a folder searched recursively for ``*.bvh`` files (the extension matched in any
case), read in the order of their relative paths (POSIX form, compared case-sensitively), so
the same folder always gives the same clips in the same order. Each clip's leading T-pose or
empty frames are dropped on loading (:func:`jcrowd.motion.clip.drop_tpose_frames`, DESIGN §4.1).

Labels come from a CSV file (``labels.csv`` in the folder unless another is named) with a header
row holding at least the columns ``file, actor, style, repetition`` (in any order; names are
matched ignoring case and surrounding spaces; other columns are ignored). ``file`` is the clip's
path relative to the folder, with or without its ``.bvh`` extension; ``repetition`` is an
integer. A blank cell reads as "unknown" (``None``), as does every label of a clip the file
does not list. Every problem is a :class:`~jcrowd.errors.DataError` naming ``path:line``.

Each clip is a :class:`~jcrowd.motion.clip.Clip` (a motion with its source and labels); the
procedural walker, the dataset the package can always make without files, is
:mod:`jcrowd.motion.walker`.
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from jcrowd.errors import DataError, where
from jcrowd.motion.clip import Clip, drop_tpose_frames

__all__ = ["LABEL_COLUMNS", "load_dataset"]

LABEL_COLUMNS = ("file", "actor", "style", "repetition")
"""Columns a labels file must have (more are allowed and ignored)."""


@dataclass(frozen=True)
class _Labels:
    """The labels of one clip; ``None`` where unknown."""

    actor: str | None = None
    style: str | None = None
    repetition: int | None = None


def load_dataset(
    folder: str | os.PathLike[str],
    *,
    labels: str | os.PathLike[str] | None = None,
    scale: float | None = None,
) -> tuple[Clip, ...]:
    """Every BVH clip under ``folder`` (recursively), sorted by relative path, with labels.

    Args:
        folder: the dataset folder.
        labels: a labels CSV; default ``folder/labels.csv`` when that file exists, else none.
        scale: file units → metres for every file; ``None`` lets the reader detect the unit.

    Returns:
        The clips, in the order of their relative paths.

    Raises:
        DataError: the folder is missing or holds no BVH file, or the labels file is invalid.
        BVHError: a BVH file is malformed (from the reader, naming ``path:line``).
    """
    from jcrowd.io.bvh import read_bvh  # io sits above the core; imported where it is used

    root = Path(folder)
    if not root.is_dir():
        what = "a file" if root.exists() else "nothing"
        raise DataError(f"{where(root)}: expected a dataset folder, found {what}")
    files = _bvh_files(root)
    if not files:
        raise DataError(f"{where(root)}: expected *.bvh files (searched recursively), found none")
    if labels is None and (root / "labels.csv").is_file():
        labels = root / "labels.csv"
    table = _read_labels(labels, root, files) if labels is not None else {}
    clips = []
    for rel in files:
        path = root / rel
        motion, dropped = drop_tpose_frames(read_bvh(path, scale=scale))
        lab = table.get(rel, _Labels())
        clips.append(Clip(str(path), motion, dropped, lab.actor, lab.style, lab.repetition))
    return tuple(clips)


def _bvh_files(root: Path) -> list[str]:
    """Relative POSIX paths of the BVH files under ``root``, sorted (case-sensitive)."""
    found = [
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.suffix.lower() == ".bvh" and p.is_file()
    ]
    return sorted(found)


def _read_labels(path: str | os.PathLike[str], root: Path, files: list[str]) -> dict[str, _Labels]:
    """Labels per clip from a CSV file, checked against the dataset's ``files``.

    Args:
        path: the labels CSV (see the module docstring for its format).
        root: the dataset folder (for messages).
        files: the dataset's BVH files as relative POSIX paths (with extension).

    Returns:
        ``{relative path: labels}`` for the clips the file lists.
    """
    if not Path(path).is_file():
        raise DataError(f"{where(path)}: expected a labels file, found none")
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        try:
            header = next(reader, None)
            while header is not None and not any(c.strip() for c in header):
                header = next(reader, None)
            if header is None:
                raise DataError(
                    f"{where(path, 1)}: expected a header row {', '.join(LABEL_COLUMNS)}, "
                    "found an empty file"
                )
            line = reader.line_num
            names = [c.strip().lower() for c in header]
            missing = [c for c in LABEL_COLUMNS if c not in names]
            if missing:
                raise DataError(
                    f"{where(path, line)}: expected columns {', '.join(LABEL_COLUMNS)} in the "
                    f"header, missing column {', '.join(repr(m) for m in missing)} (found {names})"
                )
            col = {c: names.index(c) for c in LABEL_COLUMNS}
            known = set(files)
            by_stem = {_strip_bvh(f): f for f in files}
            table: dict[str, _Labels] = {}
            first_line: dict[str, int] = {}
            for row in reader:
                line = reader.line_num
                if not any(c.strip() for c in row):
                    continue
                if len(row) < len(names):
                    raise DataError(
                        f"{where(path, line)}: expected {len(names)} fields, found {len(row)}"
                    )
                cells = {c: row[i].strip() for c, i in col.items()}
                rel = _match_file(cells["file"], known, by_stem)
                if rel is None:
                    raise DataError(
                        f"{where(path, line)}: file {cells['file']!r} does not exist "
                        f"(expected a .bvh file under {where(root)}, with or without its extension)"
                    )
                if rel in table:
                    raise DataError(
                        f"{where(path, line)}: duplicate row for {rel!r} "
                        f"(first at line {first_line[rel]})"
                    )
                table[rel] = _Labels(
                    cells["actor"] or None,
                    cells["style"] or None,
                    _repetition(cells["repetition"], path, line),
                )
                first_line[rel] = line
        except csv.Error as e:
            raise DataError(f"{where(path, reader.line_num)}: expected CSV, {e}") from None
        except UnicodeDecodeError as e:
            raise DataError(f"{where(path)}: expected UTF-8 text, {e}") from None
    return table


def _strip_bvh(name: str) -> str:
    return name[:-4] if name.lower().endswith(".bvh") else name


def _match_file(name: str, known: set[str], by_stem: dict[str, str]) -> str | None:
    """The dataset file a labels row names (relative, with or without ``.bvh``), or ``None``."""
    if not name:
        return None
    rel = PurePosixPath(name.replace("\\", "/")).as_posix()
    if rel in known:
        return rel
    return by_stem.get(rel) if not rel.lower().endswith(".bvh") else None


def _repetition(text: str, path: str | os.PathLike[str], line: int) -> int | None:
    if not text:
        return None
    if re.fullmatch(r"[+-]?[0-9]+", text) is None:
        raise DataError(f"{where(path, line)}: expected an integer repetition, found {text!r}")
    return int(text)
