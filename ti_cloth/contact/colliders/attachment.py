"""Attachments: cloth particles carried by a collider's surface (a collar on shoulders, a
waistband on hips, a cape's clasp), as Houdini Vellum's "attach to geometry" and Blender's
pin-to-surface do.

Each particle is bound at t = 0 to the collider as it is then. On an animated mesh it is
bound to its nearest triangle: the nearest point's barycentric coordinates, and the particle's
offset from that point in the triangle's own frame (first edge, in-plane normal to it,
face normal). At time t it is at the same barycentric point of the moved triangle plus the
same offset in the moved frame: a particle on the surface stays on its triangle however the
mesh deforms, one a little off it stays as far off. On a rigid collider (a shape moving
along its path, a turning mesh) it moves rigidly with the shape.

An attachment runs as a handle (physics/handles.py): its particles are pinned while it holds
and put where the surface has them after every step's integrator, with the velocity of that
move; with a `release` time they let go with it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...geometry import closest_barycentric
from ...inputs import limits
from ...inputs.validation import as_array, in_range, require
from ...physics.handles import Handle
from .animated_mesh import AnimatedMeshCollider
from .sdf import nearest_triangles
from .shapes import Collider

DEGENERATE = 1e-12      # a triangle whose doubled area is below this x its longest edge^2


@dataclass(frozen=True)
class Attachment:
    """Particles of the cloth carried by `collider`'s surface from t = 0 (module doc).

    particles: indices of the particles it carries (pinned while it holds).
    collider: the Collider that carries them: an AnimatedMeshCollider (bound to its nearest
        triangles) or any collider with a path (carried rigidly). It need not be among the
        simulation's colliders.
    release: time [s] it lets go, or None (as Handle.release).
    """

    particles: Sequence[int]
    collider: Collider
    release: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "particles", as_array("Attachment.particles", self.particles,
                                                       np.int64, (None,)))
        require(len(self.particles) > 0, "Attachment.particles", [],
                "at least one particle index")
        require(isinstance(self.collider, Collider), "Attachment.collider", self.collider,
                "a collider (tc.AnimatedMeshCollider, tc.MeshCollider, tc.Sphere, ...)")
        if self.release is not None:
            object.__setattr__(self, "release", in_range("Attachment.release", self.release,
                                                         limits.TIME))

    def handle(self, rest_position: np.ndarray) -> Handle:
        """The handle that carries these particles of a body at rest at `rest_position`."""
        count = len(rest_position)
        bad = self.particles[(self.particles < 0) | (self.particles >= count)]
        require(len(bad) == 0, "Attachment.particles", bad.tolist(),
                f"particle indices in [0, {count - 1}]")
        points = np.asarray(rest_position, np.float64)[self.particles]
        if isinstance(self.collider, AnimatedMeshCollider):
            path = SurfaceBinding(self.collider, points)
        else:
            path = RigidBinding(self.collider, points)
        return Handle(self.particles, path, self.release)


class RigidBinding:
    """t -> displacement of points fixed to a rigid collider at t = 0 (Handle.path)."""

    def __init__(self, collider: Collider, points: np.ndarray):
        self.collider, self.points = collider, points

    def __call__(self, t: float) -> np.ndarray:
        return self.collider.carried(self.points, t) - self.points


class SurfaceBinding:
    """t -> displacement of points bound to an animated mesh's nearest triangles at t = 0
    (Handle.path): barycentric on the triangle, offset in its frame (module doc)."""

    def __init__(self, collider: AnimatedMeshCollider, points: np.ndarray):
        vertices = collider.vertices_at(0.0)
        self.collider, self.points = collider, points
        self.triangle = nearest_triangles(vertices, collider.mesh.triangles, points)
        corners = collider.mesh.triangles[self.triangle]
        a, b, c = (vertices[corners[:, k]] for k in range(3))
        frame = triangle_frames(a, b, c, self.triangle)
        self.barycentric = closest_barycentric(a, b, c, points)
        foot = np.einsum("pk,pkj->pj", self.barycentric, np.stack([a, b, c], axis=1))
        self.offset = np.einsum("pij,pj->pi", frame, points - foot)
        self.corners = corners

    def __call__(self, t: float) -> np.ndarray:
        vertices = self.collider.vertices_at(t)
        a, b, c = (vertices[self.corners[:, k]] for k in range(3))
        frame = triangle_frames(a, b, c, self.triangle, t)
        foot = np.einsum("pk,pkj->pj", self.barycentric, np.stack([a, b, c], axis=1))
        return foot + np.einsum("pij,pi->pj", frame, self.offset) - self.points


def triangle_frames(a, b, c, triangle, t: float = 0.0) -> np.ndarray:
    """Orthonormal frames (P, 3, 3), rows: first edge, in-plane normal to it, face normal."""
    edge = b - a
    normal = np.cross(edge, c - a)
    area = np.linalg.norm(normal, axis=1)
    longest = np.max([np.sum(e * e, axis=1) for e in (edge, c - a, c - b)], axis=0)
    flat = area <= DEGENERATE * longest
    require(not flat.any(), f"Attachment: the collider's triangle "
            f"{triangle[flat][0] if flat.any() else ''} at t = {t:g} s", "degenerate",
            "a triangle with an area to carry a particle")
    u = edge / np.linalg.norm(edge, axis=1)[:, None]
    n = normal / area[:, None]
    return np.stack([u, np.cross(n, u), n], axis=1)
