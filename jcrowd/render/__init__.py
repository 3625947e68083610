"""Headless rendering of crowds (DESIGN §6; papers 003 §3, §6.4).

- :mod:`~jcrowd.render.camera` — :class:`View`, its matrices and :func:`project` (pure NumPy).
- :mod:`~jcrowd.render.context` — :func:`make_context`: a standalone EGL moderngl context.
- :mod:`~jcrowd.render.meshes` — capsule and ground meshes, shaders, :data:`LEVEL_COLORS`.
- :mod:`~jcrowd.render.renderer` — :class:`CrowdRenderer`: one instanced draw per LOD level.
- :mod:`~jcrowd.render.output` — :func:`write_png` and :class:`VideoWriter` (MP4/GIF), atomic.

This package never imports the crowd step: it takes joint world positions per level.
"""

from jcrowd.render.camera import View as View
from jcrowd.render.camera import frame_points as frame_points
from jcrowd.render.camera import project as project
from jcrowd.render.camera import projection_matrix as projection_matrix
from jcrowd.render.camera import view_matrix as view_matrix
from jcrowd.render.context import check_gl as check_gl
from jcrowd.render.context import gl_renderer as gl_renderer
from jcrowd.render.context import make_context as make_context
from jcrowd.render.levels import LevelInstances as LevelInstances
from jcrowd.render.levels import LevelMesh as LevelMesh
from jcrowd.render.meshes import GROUP_COLORS as GROUP_COLORS
from jcrowd.render.meshes import LEVEL_COLORS as LEVEL_COLORS
from jcrowd.render.meshes import palette_colors as palette_colors
from jcrowd.render.output import VIDEO_SUFFIXES as VIDEO_SUFFIXES
from jcrowd.render.output import VideoWriter as VideoWriter
from jcrowd.render.output import write_png as write_png
from jcrowd.render.renderer import CrowdRenderer as CrowdRenderer

__all__ = [
    "GROUP_COLORS",
    "LEVEL_COLORS",
    "VIDEO_SUFFIXES",
    "CrowdRenderer",
    "LevelInstances",
    "LevelMesh",
    "VideoWriter",
    "View",
    "check_gl",
    "frame_points",
    "gl_renderer",
    "make_context",
    "palette_colors",
    "project",
    "projection_matrix",
    "view_matrix",
    "write_png",
]
