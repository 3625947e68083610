"""The camera: a look-at view, an OpenGL perspective, and the same projection in NumPy.

Conventions (DESIGN §3): metres, Y up, right-handed world. The camera looks down its own -Z
axis with +Y up and +X to the right (OpenGL eye space); clip space is OpenGL's (NDC depth in
[-1, 1]). Image coordinates are continuous pixels with (0, 0) at the top-left corner of the
image, x to the right and y down, the same as a PNG array's ``[row, column]``: pixel
``image[j, i]`` covers ``[i, i + 1) × [j, j + 1)``, so its index is ``floor`` of the coordinate
and its centre is at ``(i + 0.5, j + 0.5)``.

Everything here is pure NumPy (float64) and needs no GL context, so tests can check where a
joint must appear without a GPU, and the renderer uses exactly these matrices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

from jcrowd.errors import RenderError

__all__ = ["View", "frame_points", "project", "projection_matrix", "view_matrix"]

_Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class View:
    """A perspective camera.

    Attributes:
        eye: camera position (m).
        target: the point it looks at (m); the optical axis runs from ``eye`` to ``target``.
        up: the world direction that appears up in the image (need not be exactly orthogonal
            to the optical axis, only not parallel to it).
        fov_deg: vertical field of view (degrees), in (0, 180).
        near, far: clipping distances along the optical axis (m), ``0 < near < far``.
    """

    eye: _Vec3
    target: _Vec3
    up: _Vec3 = (0.0, 1.0, 0.0)
    fov_deg: float = 60.0
    near: float = 0.1
    far: float = 1000.0

    def __post_init__(self) -> None:
        values = (*self.eye, *self.target, *self.up, self.fov_deg, self.near, self.far)
        if len(self.eye) != 3 or len(self.target) != 3 or len(self.up) != 3:
            raise RenderError(
                f"View: expected 3-vectors for eye, target and up, found {self.eye}, "
                f"{self.target}, {self.up}"
            )
        if not all(math.isfinite(v) for v in values):
            raise RenderError(f"View: expected finite numbers, found {self}")
        if not 0.0 < self.fov_deg < 180.0:
            raise RenderError(f"View: expected 0 < fov_deg < 180, found {self.fov_deg}")
        if not 0.0 < self.near < self.far:
            raise RenderError(
                f"View: expected 0 < near < far, found near={self.near}, far={self.far}"
            )
        forward = np.subtract(self.target, self.eye, dtype=np.float64)
        norm = float(np.linalg.norm(forward))
        if norm == 0.0:
            raise RenderError(f"View: eye and target coincide at {self.eye}")
        side = np.cross(forward / norm, np.asarray(self.up, np.float64))
        if float(np.linalg.norm(side)) < 1e-9:
            raise RenderError(
                f"View: up {self.up} is parallel to the viewing direction {tuple(forward)}"
            )


def view_matrix(view: View) -> Float[np.ndarray, "4 4"]:
    """World → eye transform (4×4, float64): the camera at the origin looking down -Z, +Y up."""
    eye = np.asarray(view.eye, np.float64)
    f = np.asarray(view.target, np.float64) - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, np.asarray(view.up, np.float64))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def projection_matrix(view: View, width: int, height: int) -> Float[np.ndarray, "4 4"]:
    """Eye → OpenGL clip space (4×4, float64) for an image of ``width × height`` pixels.

    The symmetric perspective frustum with vertical field of view ``view.fov_deg`` and aspect
    ``width / height``; eye depth ``-near`` maps to NDC depth -1 and ``-far`` to +1.
    """
    if width <= 0 or height <= 0:
        raise RenderError(f"projection: expected a positive image size, found {width}×{height}")
    t = 1.0 / math.tan(math.radians(view.fov_deg) / 2.0)
    n, f = view.near, view.far
    p = np.zeros((4, 4))
    p[0, 0] = t * height / width
    p[1, 1] = t
    p[2, 2] = (f + n) / (n - f)
    p[2, 3] = 2.0 * f * n / (n - f)
    p[3, 2] = -1.0
    return p


def project(
    points: Float[np.ndarray, "*batch 3"], view: View, width: int, height: int
) -> tuple[Float[np.ndarray, "*batch 2"], Bool[np.ndarray, " *batch"]]:
    """Where world ``points`` (m) land in a ``width × height`` image seen through ``view``.

    Returns:
        ``(pixels, in_front)``: ``pixels (..., 2)`` float64 continuous image coordinates
        (x right, y down, (0, 0) the top-left corner; see the module docstring), and
        ``in_front (...)`` bool, True where the point lies beyond the near plane (eye depth
        > ``near``). Points not in front have meaningless pixels (a point behind the camera
        would project mirrored) and are never drawn. Points beyond ``far`` or outside the
        image are also not drawn; check ``0 <= pixels < (width, height)`` for the latter.
    """
    p = np.asarray(points, np.float64)
    if p.shape[-1:] != (3,):
        raise RenderError(f"project: expected points of shape (..., 3), found {p.shape}")
    homo = np.concatenate([p, np.ones((*p.shape[:-1], 1))], axis=-1)
    eye = homo @ view_matrix(view).T
    clip = eye @ projection_matrix(view, width, height).T
    in_front = -eye[..., 2] > view.near
    # Points at or behind the eye plane have w <= 0; keep the division finite (their pixels are
    # documented as meaningless) rather than producing inf/NaN warnings.
    w = np.where(in_front, clip[..., 3], 1.0)
    ndc = clip[..., :2] / w[..., None]
    x = (ndc[..., 0] + 1.0) * 0.5 * width
    y = (1.0 - ndc[..., 1]) * 0.5 * height  # NDC +y is up, image rows go down
    return np.stack([x, y], axis=-1), in_front


def frame_points(
    points: Float[np.ndarray, "N 3"],
    *,
    direction: _Vec3 = (0.0, 0.6, 1.0),
    fov_deg: float = 45.0,
    aspect: float = 16.0 / 9.0,
    margin: float = 1.1,
) -> View:
    """A view that looks at the centre of ``points`` and fits them all in the image.

    The camera sits along ``direction`` (from the centre towards the eye, need not be unit)
    far enough that the bounding sphere of the points, enlarged by ``margin``, fits inside both
    the vertical and the horizontal field of view of an image of the given ``aspect``.
    ``near`` is set just short of the sphere so depth precision is not wasted; ``far`` reaches
    well past it (at least 300 m) so the ground plane runs on towards the horizon.
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if len(p) == 0 or not np.all(np.isfinite(p)):
        raise RenderError("frame_points: expected at least one finite point")
    d = np.asarray(direction, np.float64)
    if float(np.linalg.norm(d)) == 0.0:
        raise RenderError("frame_points: expected a non-zero direction")
    d /= np.linalg.norm(d)
    lo, hi = p.min(0), p.max(0)
    centre = (lo + hi) / 2.0
    radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 0.5) * margin
    half_v = math.radians(fov_deg) / 2.0
    half_h = math.atan(math.tan(half_v) * aspect)
    dist = radius / math.sin(min(half_v, half_h))
    eye = centre + dist * d
    return View(
        eye=(float(eye[0]), float(eye[1]), float(eye[2])),
        target=(float(centre[0]), float(centre[1]), float(centre[2])),
        fov_deg=fov_deg,
        near=max(dist - radius, 0.05) * 0.5,
        far=max((dist + radius) * 4.0, 300.0),
    )
