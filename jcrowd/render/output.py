"""Frames to files: PNG stills and MP4/GIF clips, always written atomically.

A file appears under its final name only once it is complete: PNGs go through
:func:`jcrowd.io.atomic.write_atomic`; a clip is encoded into a hidden temporary file in the
target's folder (``.NAME.XXXX.mp4``) and renamed over the target when the writer closes
without error. On error, or when the ``with`` block raises, the temporary file is removed and
an existing target is left untouched.

MP4 is H.264 (``libx264``, ``yuv420p`` so every player opens it, ``+faststart`` so it streams)
encoded by the ffmpeg binary that imageio-ffmpeg ships; yuv420p needs an even width and
height. We start ffmpeg ourselves rather than through ``imageio_ffmpeg.write_frames``: that
helper forks with a ``preexec_fn``, which runs fork handlers in a process that JAX has made
multithreaded (JAX warns of deadlocks), while a plain ``Popen`` spawns without them. GIF goes
through imageio's Pillow plugin.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import tempfile
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from jcrowd.errors import RenderError, where
from jcrowd.io.atomic import write_atomic

__all__ = ["VIDEO_SUFFIXES", "VideoWriter", "write_png"]

VIDEO_SUFFIXES = (".mp4", ".gif")
"""File suffixes :class:`VideoWriter` can write."""

_FFMPEG_TIMEOUT_S = 120.0  # finishing a clip (flush + faststart rewrite) never takes this long


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write an ``(H, W, 3)`` or ``(H, W, 4)`` uint8 image (row 0 on top) as a PNG, atomically.

    Raises:
        RenderError: a wrong shape or dtype, or the file cannot be written (naming the path).
    """
    img = _check_image(image, f"write_png {where(path)}", channels=(3, 4))
    write_atomic(path, iio.imwrite("<bytes>", img, extension=".png"), error=RenderError)


class VideoWriter:
    """Write frames to an MP4 or GIF clip; use as a context manager.

    Example::

        with VideoWriter("out/crowd.mp4", fps=30) as video:
            for frame in frames:
                video.append(frame)

    Args:
        path: the clip to write; its suffix (``.mp4`` or ``.gif``) picks the format.
        fps: frames per second (> 0).
        crf: H.264 constant rate factor for MP4, 0 (lossless) to 51 (worst); 20 keeps thin
            bones and grid lines sharp at modest size.

    The first frame fixes the size; every frame must be ``(H, W, 3)`` uint8 of that size, and
    for MP4 ``H`` and ``W`` must be even. Nothing exists under ``path`` until :meth:`close`
    succeeds; a clip with no frames is an error.
    """

    def __init__(self, path: str | os.PathLike[str], fps: float = 30.0, *, crf: int = 20):
        self.path = Path(path)
        self.suffix = self.path.suffix.lower()
        if self.suffix not in VIDEO_SUFFIXES:
            raise RenderError(
                f"{where(path)}: expected a clip ending in {' or '.join(VIDEO_SUFFIXES)}, "
                f"found {self.path.suffix or 'no suffix'}"
            )
        if not fps > 0:
            raise RenderError(f"{where(path)}: expected a positive frame rate, found {fps}")
        if not 0 <= crf <= 51:
            raise RenderError(f"{where(path)}: expected crf in [0, 51], found {crf}")
        self.fps, self.crf = float(fps), int(crf)
        self.frames_written = 0
        self._size: tuple[int, int] | None = None  # (height, width), fixed by the first frame
        self._tmp: str | None = None
        self._ffmpeg: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None  # ffmpeg's stderr, read back for error messages
        self._gif_frames: list[np.ndarray] = []
        self._closed = False

    def append(self, frame: np.ndarray) -> None:
        """Add one ``(H, W, 3)`` uint8 frame (row 0 on top)."""
        if self._closed:
            raise RenderError(f"{where(self.path)}: the video writer is closed")
        img = _check_image(frame, where(self.path), channels=(3,))
        h, w = img.shape[:2]
        if self._size is None:
            if self.suffix == ".mp4" and (h % 2 or w % 2):
                raise RenderError(
                    f"{where(self.path)}: MP4 (H.264, yuv420p) needs an even width and height, "
                    f"found {w}×{h}"
                )
            self._size = (h, w)
            self._open()
        elif self._size != (h, w):
            raise RenderError(
                f"{where(self.path)}: frame {self.frames_written} is {w}×{h}, the clip is "
                f"{self._size[1]}×{self._size[0]}"
            )
        if self._ffmpeg is None:
            self._gif_frames.append(img.copy())
        else:
            stdin = self._ffmpeg.stdin
            try:
                if stdin is None:
                    raise OSError("ffmpeg has no input pipe")
                stdin.write(np.ascontiguousarray(img).tobytes())
            except OSError as e:  # BrokenPipeError when ffmpeg has died
                log = self._ffmpeg_log()
                self.abort()
                raise RenderError(
                    f"{where(self.path)}: ffmpeg stopped at frame {self.frames_written}: {e}; {log}"
                ) from e
        self.frames_written += 1

    def close(self) -> None:
        """Finish the clip and move it to ``path``. Idempotent once it has succeeded."""
        if self._closed:
            return
        tmp = self._tmp
        if self.frames_written == 0 or tmp is None:
            self.abort()
            raise RenderError(f"{where(self.path)}: no frames were written")
        try:
            if self._ffmpeg is not None:
                self._finish_ffmpeg()
            else:
                iio.imwrite(
                    tmp,
                    np.stack(self._gif_frames),
                    extension=".gif",
                    duration=1000.0 / self.fps,  # Pillow wants milliseconds per frame
                    loop=0,
                )
                self._gif_frames = []
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
            os.chmod(tmp, 0o644)  # mkstemp made it private
            os.replace(tmp, self.path)
        except (OSError, ValueError, subprocess.SubprocessError) as e:
            self.abort()
            raise RenderError(f"{where(self.path)}: cannot finish the clip: {e}") from e
        self._tmp = None
        self._closed = True

    def abort(self) -> None:
        """Stop without writing ``path``: end ffmpeg and remove the temporary file."""
        self._closed = True
        if self._ffmpeg is not None:
            if self._ffmpeg.stdin is not None:
                with contextlib.suppress(OSError):
                    self._ffmpeg.stdin.close()
            self._ffmpeg.kill()
            self._ffmpeg.wait()
            self._ffmpeg = None
        if self._log is not None:
            self._log.close()
            self._log = None
        self._gif_frames = []
        if self._tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(self._tmp)
            self._tmp = None

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def _open(self) -> None:
        """Create the temporary file and, for MP4, start ffmpeg encoding into it."""
        try:
            fd, self._tmp = tempfile.mkstemp(
                dir=self.path.resolve().parent, prefix=f".{self.path.name}.", suffix=self.suffix
            )
            os.close(fd)
        except OSError as e:
            self._closed = True
            raise RenderError(f"{where(self.path)}: cannot write: {e.strerror or e}") from e
        if self.suffix != ".mp4" or self._size is None:
            return
        h, w = self._size
        # Input: raw RGB frames on stdin. Output: H.264 yuv420p into the temporary file.
        cmd: list[str] = [
            imageio_ffmpeg.get_ffmpeg_exe(),
            *("-y", "-hide_banner", "-loglevel", "error", "-nostdin"),
            *("-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", f"{self.fps:g}"),
            *("-i", "pipe:0", "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p"),
            *("-crf", str(self.crf), "-movflags", "+faststart", "-f", "mp4", self._tmp),
        ]
        try:
            self._log = tempfile.TemporaryFile()
            self._ffmpeg = subprocess.Popen(
                cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._log
            )
        except (OSError, RuntimeError) as e:
            self.abort()
            raise RenderError(f"{where(self.path)}: cannot start ffmpeg: {e}") from e

    def _finish_ffmpeg(self) -> None:
        """Close ffmpeg's input, wait for it, and raise if it failed."""
        proc = self._ffmpeg
        if proc is None or proc.stdin is None:
            return
        proc.stdin.close()
        code = proc.wait(timeout=_FFMPEG_TIMEOUT_S)
        log = self._ffmpeg_log()
        self._ffmpeg = None
        if self._log is not None:
            self._log.close()
            self._log = None
        if code != 0:
            raise OSError(f"ffmpeg exited with status {code}; {log}")

    def _ffmpeg_log(self) -> str:
        """The last lines ffmpeg wrote to stderr (for error messages)."""
        if self._log is None:
            return "ffmpeg said nothing"
        with contextlib.suppress(OSError):
            self._log.seek(0)
            text = self._log.read().decode("utf-8", "replace").strip()
            return f"ffmpeg said: {text[-500:]}" if text else "ffmpeg said nothing"
        return "ffmpeg's log is unreadable"


def _check_image(image: Any, context: str, channels: tuple[int, ...]) -> np.ndarray:
    """``image`` as a NumPy uint8 array of shape ``(H, W, C)`` with ``C`` in ``channels``."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in channels or img.shape[0] < 1 or img.shape[1] < 1:
        wanted = " or ".join(f"(H, W, {c})" for c in channels)
        raise RenderError(f"{context}: expected an image of shape {wanted}, found {img.shape}")
    if img.dtype != np.uint8:
        raise RenderError(f"{context}: expected a uint8 image, found {img.dtype}")
    return img
