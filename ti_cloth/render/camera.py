"""Look-at cameras: perspective (vertical field of view) or orthographic (visible height).

Screen convention shared with the rasteriser: x to the right, y up, origin at the bottom-left
corner of the image, pixel (x, y) covering [x, x + 1) x [y, y + 1) with its centre at
(x + 0.5, y + 0.5) — Taichi's layout; `image.from_taichi` turns it into a top-left numpy image.
Depth is the distance along the viewing direction [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..inputs import limits
from ..inputs.validation import as_array, finite_number, in_range, keyword_only, require

DEFAULT_DIRECTION = (0.55, 0.4, 1.0)   # from the target towards the camera: front-right, above


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Camera:
    """position, target [m]; up: which way is up on screen (need not be exactly perpendicular).

    fov: vertical field of view [deg] of the perspective camera, in [1, 170] (limits.FOV).
    orthographic: parallel projection showing `height` metres vertically instead.
    near: nothing closer than this depth [m] is drawn.
    """

    position: tuple = (0.0, 0.0, 3.0)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 40.0
    orthographic: bool = False
    height: float = 2.0
    near: float = 1e-3

    def __post_init__(self):
        for name in ("position", "target", "up"):
            value = as_array(f"Camera.{name}", getattr(self, name), np.float64, (3,))
            object.__setattr__(self, name, tuple(float(v) for v in value))
        forward = np.subtract(self.target, self.position)
        require(np.linalg.norm(forward) > 0, "Camera.target", self.target,
                f"a point other than Camera.position {self.position}")
        forward = forward / np.linalg.norm(forward)
        up = np.asarray(self.up)
        require(np.linalg.norm(np.cross(forward, up)) > 1e-6 * max(np.linalg.norm(up), 1e-300),
                "Camera.up", self.up, "a direction not parallel to the viewing direction")
        object.__setattr__(self, "fov", in_range("Camera.fov", self.fov, limits.FOV))
        object.__setattr__(self, "height", finite_number("Camera.height", self.height, 0.0,
                                                         strict=True, unit="m"))
        object.__setattr__(self, "near", finite_number("Camera.near", self.near, 0.0,
                                                       strict=True, unit="m"))
        require(isinstance(self.orthographic, bool), "Camera.orthographic", self.orthographic,
                "True or False")

    @classmethod
    def fit(cls, body, *, direction=DEFAULT_DIRECTION, up=(0.0, 1.0, 0.0), fov: float = 40.0,
            orthographic: bool = False, aspect: float = 16 / 9, margin: float = 1.1) -> Camera:
        """A camera that frames `body` (a Mesh, a Cloth, an (N, 3) array of points or bounds
        ((x0, y0, z0), (x1, y1, z1))) seen from `direction` (target -> camera), its bounding
        sphere filling the view with `margin` to spare in an image of width/height `aspect`."""
        lo, hi = bounds_of(body)
        centre, radius = (lo + hi) / 2, max(np.linalg.norm(hi - lo) / 2, 1e-3)
        direction = as_array("direction", direction, np.float64, (3,))
        require(np.linalg.norm(direction) > 0, "direction", tuple(direction), "a non-zero vector")
        direction = direction / np.linalg.norm(direction)
        aspect = finite_number("aspect", aspect, 0.0, strict=True)
        margin = finite_number("margin", margin, 0.0, strict=True)
        reach = radius * margin
        if orthographic:       # parallel rays: stand just outside the sphere, show its diameter
            distance, height = 2 * reach, 2 * reach / min(1.0, aspect)
        else:                  # the sphere touches the narrower of the two view cones
            half_angle = math.atan(math.tan(math.radians(fov) / 2) * min(1.0, aspect))
            distance, height = reach / math.sin(half_angle), 2.0
        return cls(position=tuple(centre + distance * direction), target=tuple(centre), up=up,
                   fov=fov, orthographic=orthographic, height=height,
                   near=(distance - reach) / 10)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, forward) unit vectors, right-handed, forward from position to target."""
        forward = np.subtract(self.target, self.position)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right /= np.linalg.norm(right)
        return right, np.cross(right, forward), forward

    def scale(self, image_height: int) -> float:
        """Pixels per metre at depth 1 m (perspective) or at any depth (orthographic)."""
        if self.orthographic:
            return image_height / self.height
        return image_height / 2 / math.tan(math.radians(self.fov) / 2)

    def packed(self, width: int, height: int) -> np.ndarray:
        """The camera as the rasteriser reads it (raster.camera_of): eye, right, up, forward,
        then pixels-per-metre scale, image centre x, y, orthographic flag, near plane."""
        right, up, forward = self.basis()
        return np.concatenate([self.position, right, up, forward,
                               [self.scale(height), width / 2, height / 2,
                                float(self.orthographic), self.near]]).astype(np.float32)

    def project(self, points, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Screen coordinates (N, 2) [pixels, bottom-left origin] and depth (N,) [m] of world
        points, in float64 (the rasteriser does the same in its own precision)."""
        points = np.atleast_2d(np.asarray(points, np.float64))
        right, up, forward = self.basis()
        v = points - np.asarray(self.position)
        depth = v @ forward
        w = np.ones_like(depth) if self.orthographic else depth
        screen = self.scale(height) * np.stack([v @ right, v @ up], axis=1) / w[:, None]
        return screen + np.array([width / 2, height / 2]), depth


def bounds_of(body) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners [m] of a Mesh, a Cloth, an (N, 3) point array or a (2, 3) bounds pair."""
    points = getattr(body, "particle_position", getattr(body, "vertices", body))
    points = as_array("body points", points, np.float64, (None, 3))
    require(len(points) > 0, "body points", points.shape, "at least one point")
    return points.min(axis=0), points.max(axis=0)
