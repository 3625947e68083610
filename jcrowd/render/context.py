"""The one place a GL context is made, and the GL error check every draw ends with.

jcrowd renders headless only: a standalone OpenGL 3.3+ core context through EGL, with no X
server and no window. EGL picks the GPU driver where one is installed (NVIDIA, Mesa radeonsi/
iris, …) and Mesa's llvmpipe software rasteriser otherwise; both are plain EGL devices, so the
same code path serves a laptop, a CI container and a GPU node.
"""

from __future__ import annotations

import ctypes.util
from typing import Any

import moderngl

from jcrowd.errors import RenderError

__all__ = ["check_gl", "gl_renderer", "make_context"]

_MIN_VERSION = 330  # GLSL 330 core: instanced attributes with divisors, integer maths, MSAA.

_INSTALL = (
    "Install the EGL loader and an OpenGL driver (Mesa provides a software one): "
    "Debian/Ubuntu `apt install libegl1 libgl1 libgl1-mesa-dri`, "
    "Fedora `dnf install mesa-libEGL mesa-libGL mesa-dri-drivers`, "
    "conda `conda install -c conda-forge mesalib libglvnd`."
)


def make_context(device_index: int | None = None) -> moderngl.Context:
    """A standalone headless moderngl context (EGL, OpenGL ≥ 3.3 core).

    Args:
        device_index: which EGL device to use (0 = the first the driver lists, usually the GPU
            where there is one). ``None`` leaves the choice to glcontext, which also honours
            ``$GLCONTEXT_DEVICE_INDEX``.

    Raises:
        RenderError: naming the missing system library, or the underlying EGL/GL error, and
            how to install what is missing.
    """
    missing = [name for name in ("EGL", "GL") if ctypes.util.find_library(name) is None]
    if missing:
        libs = " and ".join(f"lib{name}.so" for name in missing)
        raise RenderError(f"cannot make a headless OpenGL context: {libs} not found. {_INSTALL}")
    settings: dict[str, Any] = {"standalone": True, "backend": "egl"}
    if device_index is not None:
        settings["device_index"] = device_index
    try:
        ctx = moderngl.create_context(**settings)
    except Exception as e:  # glcontext raises plain Exceptions with the EGL error in the text
        raise RenderError(
            f"cannot make a headless OpenGL context through EGL: {type(e).__name__}: {e}. "
            f"{_INSTALL}"
        ) from e
    if ctx.version_code < _MIN_VERSION:
        found = ctx.info.get("GL_VERSION", ctx.version_code)
        ctx.release()
        raise RenderError(
            f"the OpenGL driver offers version {found}; jcrowd needs OpenGL "
            f"{_MIN_VERSION // 100}.{_MIN_VERSION % 100 // 10} core. {_INSTALL}"
        )
    return ctx


def gl_renderer(ctx: moderngl.Context) -> str:
    """The driver's ``GL_RENDERER`` string, e.g. ``"llvmpipe (LLVM 15.0.6, 256 bits)"``."""
    return str(ctx.info.get("GL_RENDERER", "unknown"))


def check_gl(ctx: moderngl.Context, during: str) -> None:
    """Raise :class:`RenderError` if the GL error flag is set (``glGetError`` clears it).

    Args:
        during: what was being done, for the message (e.g. ``"render"``).
    """
    error = ctx.error
    if error != "GL_NO_ERROR":
        raise RenderError(f"OpenGL error during {during}: {error} ({gl_renderer(ctx)})")
