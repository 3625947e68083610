"""Atomic file writes: a temporary file in the target's folder, fsynced, then renamed over it.

A reader never sees a half-written file, and a failure (full disk, Ctrl-C, a bug) leaves any
existing target untouched and no temporary file behind.
"""

from __future__ import annotations

import contextlib
import os
import tempfile

from jcrowd.errors import JcrowdError, where

__all__ = ["write_atomic"]


def write_atomic(
    path: str | os.PathLike[str], data: str | bytes, *, error: type[JcrowdError] = JcrowdError
) -> None:
    """Write ``data`` (text as UTF-8 with ``\\n`` line ends, or bytes) to ``path`` atomically.

    An ``OSError`` becomes ``error`` naming the path; anything else is re-raised as it is.
    """
    path = os.fspath(path)
    tmp = None
    try:
        folder, name = os.path.split(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            # mkstemp makes the file private (0600): give it the target's mode, or 0644.
            os.fchmod(fd, os.stat(path).st_mode & 0o777 if os.path.exists(path) else 0o644)
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
            f.flush()
            os.fsync(fd)
        os.replace(tmp, path)
    except BaseException as e:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        if isinstance(e, OSError):
            raise error(f"{where(path)}: cannot write: {e.strerror or e}") from e
        raise
