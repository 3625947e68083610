"""Frames to files: PNG stills and MP4/GIF clips, always written atomically.

A file appears under its final name only once it is complete: PNGs go through
:func:`jcrowd.io.atomic.write_atomic`; a clip is encoded into a hidden temporary file in the
target's folder (``.NAME.XXXX.mp4``) and renamed over the target when the writer closes
without error. On error, or when the ``with`` block raises, the temporary file is removed and
an existing target is left untouched.

MP4 is H.264 (``libx264``, ``yuv420p`` so every player opens it) through the ffmpeg binary
that imageio-ffmpeg ships; yuv420p needs an even width and height. GIF goes through Pillow.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Generator
from pathlib import Path
from types import TracebackType
from typing import Any

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from jcrowd.errors import RenderError, where
from jcrowd.io.atomic import write_atomic

__all__ = ["VIDEO_SUFFIXES", "VideoWriter", "write_png"]

VIDEO_SUFFIXES = (".mp4", ".gif")
"""File suffixes :class:`VideoWriter` can write."""


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
        quality: MP4 quality from 0 (worst) to 10 (best); 7 keeps thin bones and grid lines
            sharp at modest size.

    The first frame fixes the size; every frame must be ``(H, W, 3)`` uint8 of that size, and
    for MP4 ``H`` and ``W`` must be even. Nothing exists under ``path`` until :meth:`close`
    succeeds; a clip with no frames is an error.
    """

    def __init__(self, path: str | os.PathLike[str], fps: float = 30.0, *, quality: float = 7.0):
        self.path = Path(path)
        self.suffix = self.path.suffix.lower()
        if self.suffix not in VIDEO_SUFFIXES:
            raise RenderError(
                f"{where(path)}: expected a clip ending in {' or '.join(VIDEO_SUFFIXES)}, "
                f"found {self.path.suffix or 'no suffix'}"
            )
        if not fps > 0:
            raise RenderError(f"{where(path)}: expected a positive frame rate, found {fps}")
        if not 0 <= quality <= 10:
            raise RenderError(f"{where(path)}: expected quality in [0, 10], found {quality}")
        self.fps, self.quality = float(fps), float(quality)
        self.frames_written = 0
        self._size: tuple[int, int] | None = None  # (height, width)
        self._tmp: str | None = None
        self._encoder: Generator[Any, Any, None] | None = None
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
        try:
            if self._encoder is not None:
                self._encoder.send(np.ascontiguousarray(img))
            else:
                self._gif_frames.append(img.copy())
        except (OSError, RuntimeError) as e:
            self.abort()
            raise RenderError(
                f"{where(self.path)}: encoding frame {self.frames_written}: {e}"
            ) from e
        self.frames_written += 1

    def close(self) -> None:
        """Finish the clip and move it to ``path``. Idempotent once it has succeeded."""
        if self._closed:
            return
        if self.frames_written == 0:
            self.abort()
            raise RenderError(f"{where(self.path)}: no frames were written")
        tmp = self._tmp
        if tmp is None:  # cannot happen: the first append opens it
            raise RenderError(f"{where(self.path)}: the clip was never opened")
        try:
            if self._encoder is not None:
                self._encoder.close()  # waits for ffmpeg to finish the file
                self._encoder = None
            else:
                duration_ms = 1000.0 / self.fps
                iio.imwrite(
                    tmp,
                    np.stack(self._gif_frames),
                    extension=".gif",
                    duration=duration_ms,
                    loop=0,
                )
                self._gif_frames = []
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
            os.chmod(tmp, 0o644)
            os.replace(tmp, self.path)
        except (OSError, RuntimeError, ValueError) as e:
            self.abort()
            raise RenderError(f"{where(self.path)}: cannot finish the clip: {e}") from e
        self._tmp = None
        self._closed = True

    def abort(self) -> None:
        """Stop without writing ``path``: end the encoder and remove the temporary file."""
        self._closed = True
        if self._encoder is not None:
            with contextlib.suppress(Exception):  # the encoder may already be broken
                self._encoder.close()
            self._encoder = None
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
        """Create the temporary file and, for MP4, start ffmpeg writing into it."""
        folder = self.path.resolve().parent
        try:
            fd, self._tmp = tempfile.mkstemp(
                dir=folder, prefix=f".{self.path.name}.", suffix=self.suffix
            )
            os.close(fd)
        except OSError as e:
            self._closed = True
            raise RenderError(f"{where(self.path)}: cannot write: {e.strerror or e}") from e
        if self.suffix != ".mp4":
            return
        h, w = self._size or (0, 0)
        try:
            self._encoder = imageio_ffmpeg.write_frames(
                self._tmp,
                (w, h),
                fps=self.fps,
                codec="libx264",
                pix_fmt_out="yuv420p",
                quality=self.quality,
                macro_block_size=1,  # sizes are checked to be even above; never rescale
                output_params=["-movflags", "+faststart"],
            )
            self._encoder.send(None)  # start the generator (launches ffmpeg)
        except (OSError, RuntimeError) as e:
            self.abort()
            raise RenderError(f"{where(self.path)}: cannot start ffmpeg: {e}") from e


def _check_image(image: Any, context: str, channels: tuple[int, ...]) -> np.ndarray:
    """``image`` as a NumPy uint8 array of shape ``(H, W, C)`` with ``C`` in ``channels``."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in channels or img.shape[0] < 1 or img.shape[1] < 1:
        wanted = " or ".join(f"(H, W, {c})" for c in channels)
        raise RenderError(f"{context}: expected an image of shape {wanted}, found {img.shape}")
    if img.dtype != np.uint8:
        raise RenderError(f"{context}: expected a uint8 image, found {img.dtype}")
    return img
