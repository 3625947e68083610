"""The scenario's camera: fixed or keyed (eye and target interpolated between keys).

Part of the scenario data model (:mod:`jcrowd.scenario.schema`, whose conventions hold here:
metres and seconds, y up, a bad field a :class:`~jcrowd.errors.ScenarioError` naming its key).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from jcrowd.scenario.check import Raw, is_int, real, reals, require, show

__all__ = ["Camera", "CameraKey", "camera_at"]


@dataclass(frozen=True, eq=False)
class CameraKey:
    """The camera at ``time`` (s): ``eye`` and ``target`` ``[x, y, z]`` (m); the view must not be
    vertical, since the camera's up is +y."""

    time: float
    eye: Float[np.ndarray, " 3"]
    target: Float[np.ndarray, " 3"]

    def __post_init__(self) -> None:
        require(real(self.time), "time", "a time in seconds", self.time)
        object.__setattr__(self, "time", float(self.time))
        eye = reals(self.eye, "eye", "[x, y, z] (m)", 3)
        target = reals(self.target, "target", "[x, y, z] (m)", 3)
        view = target - eye
        level = math.hypot(view[0], view[2]) > 1e-6 * float(np.linalg.norm(view))
        require(level, "target", f"a point off the vertical through eye {show(eye)}", target)
        object.__setattr__(self, "eye", eye)
        object.__setattr__(self, "target", target)


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera, fixed (one key) or moving (eye and target interpolated between keys).

    ``fov_deg`` is the vertical field of view (1–170°); ``width`` × ``height`` the image in pixels
    (positive, even); ``near`` and ``far`` the clip distances (0 < near < far, metres). Key times
    strictly increase; before the first key and after the last the camera holds still.
    """

    keys: tuple[CameraKey, ...]
    fov_deg: float = 60.0
    width: int = 1280
    height: int = 720
    near: float = 0.1
    far: float = 1000.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "keys", tuple(self.keys))
        require(self.keys, "keys", "at least one camera key", Raw("none"))
        for i in range(1, len(self.keys)):
            t0, t1 = self.keys[i - 1].time, self.keys[i].time
            require(t1 > t0, f"keys[{i}].time", f"a time after keys[{i - 1}].time = {t0!r}", t1)
        fov = self.fov_deg
        require(real(fov) and 1 <= fov <= 170, "fov", "degrees in [1, 170]", fov)
        for key in ("width", "height"):
            v = getattr(self, key)
            ok = is_int(v) and v > 0 and v % 2 == 0
            require(ok, key, "a positive even number of pixels", v)
        require(real(self.near) and self.near > 0, "near", "a distance > 0 (m)", self.near)
        ok = real(self.far) and self.far > self.near
        require(ok, "far", f"a distance > near = {self.near!r} (m)", self.far)
        for name in ("fov_deg", "near", "far"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))


def camera_at(camera: Camera, t: float) -> tuple[Float[np.ndarray, " 3"], Float[np.ndarray, " 3"]]:
    """``(eye, target)`` at time ``t`` (s): linear between the keys around it, held outside."""
    times = np.array([k.time for k in camera.keys])
    if t <= times[0]:
        return camera.keys[0].eye.copy(), camera.keys[0].target.copy()
    if t >= times[-1]:
        return camera.keys[-1].eye.copy(), camera.keys[-1].target.copy()
    i = int(np.searchsorted(times, t, side="right")) - 1
    a, b = camera.keys[i], camera.keys[i + 1]
    s = (t - a.time) / (b.time - a.time)
    return a.eye + s * (b.eye - a.eye), a.target + s * (b.target - a.target)
