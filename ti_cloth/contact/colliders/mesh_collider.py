"""A triangle mesh as a collider: a table, a character, a bowl, moving along a path and turning.

The mesh's signed distance grid (sdf.py) is built once and sampled trilinearly in the collision
kernels (collision.py), which give it the response every collider has (colliders.py): projection
to `thickness` along the distance's gradient and Coulomb friction at position level, measured
against the motion of the surface point under the particle (a turntable carries cloth round).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ...body.mesh import Mesh, triangle_edges, unique_rows
from ...inputs import limits
from ...inputs.validation import as_array, count, require
from .sdf import DistanceGrid, distance_grid, layout
from .shapes import MESH, Collider

MARGIN = 0.1          # the grid reaches this fraction of the mesh's largest extent beyond it
ROTATION_TOLERANCE = 1e-6


@dataclass(frozen=True, kw_only=True)
class MeshCollider(Collider):
    """The triangle mesh `mesh` [m] (a Mesh with triangles; load_mesh reads files) as a collider.

    rotation: t [s] -> the mesh's rotation about its centre (the middle of its bounding box),
        as a rotation vector (axis x angle [rad], shape (3,)) or a 3x3 rotation matrix; applied
        before the translation `path`. None: it does not turn.
    resolution: cells of the distance grid along the longest side of the box around the mesh
        (the mesh's bounding box grown by a tenth of its size, or by 2 x thickness if more).
        Features thinner than a cell are rounded off; the grid costs resolution^3 x 16 bytes.
    solid: True: the inside (generalised winding number > 1/2) is solid, a particle found in it
        is pushed out through the nearest surface; False: a two-sided shell, each particle kept
        `thickness` away on the side it was on at the step's start (keep thickness above one
        cell); None: solid when the mesh is closed (every edge, after merging vertices at equal
        positions, shared by exactly two triangles), a shell otherwise (an open bowl, a plane).
    """

    mesh: Mesh = field(kw_only=False)
    rotation: Callable[[float], object] | None = None
    resolution: int = 64
    solid: bool | None = None

    def __post_init__(self):
        super().__post_init__()
        mesh = self.mesh
        require(isinstance(mesh, Mesh) and mesh.triangle_count > 0, "MeshCollider.mesh", mesh,
                "a Mesh with at least one triangle")
        extent = np.ptp(mesh.vertices, axis=0).max()
        require(extent > 0, "MeshCollider.mesh", mesh, "a Mesh whose vertices are not all at one point")
        count("MeshCollider.resolution", self.resolution, limits.SDF_RESOLUTION)
        require(self.rotation is None or callable(self.rotation), "MeshCollider.rotation",
                self.rotation, "None or a callable t -> rotation vector [rad] or 3x3 matrix")
        require(self.solid is None or isinstance(self.solid, bool), "MeshCollider.solid",
                self.solid, "True, False or None (solid when the mesh is closed)")
        if self.solid is None:
            object.__setattr__(self, "solid", closed(mesh))
        self.turn(0.0)
        cell = layout(mesh.vertices, self.resolution, self.margin)[1]
        if not self.solid and self.thickness is not None and self.thickness < cell:
            warnings.warn(f"MeshCollider: this shell's thickness ({self.thickness:g} m) is less "
                          f"than its distance grid's cell ({cell:.3g} m), so particles may come "
                          f"nearer than the thickness; raise the thickness or the resolution "
                          f"(now {self.resolution})", UserWarning, stacklevel=3)

    @property
    def centre(self) -> np.ndarray:
        """The middle of the mesh's bounding box [m]: the pivot of `rotation`."""
        return 0.5 * (self.mesh.vertices.min(axis=0) + self.mesh.vertices.max(axis=0))

    @property
    def margin(self) -> float:
        """How far the distance grid reaches beyond the mesh's bounding box [m]."""
        return max(MARGIN * float(np.ptp(self.mesh.vertices, axis=0).max()),
                   2 * (self.thickness or 0.0))

    def grid(self) -> DistanceGrid:
        """The mesh's signed distance grid (built once, cached: sdf.distance_grid)."""
        return distance_grid(self.mesh.vertices, self.mesh.triangles, self.resolution,
                             self.margin)

    def turn(self, t: float) -> np.ndarray:
        """The rotation matrix (3, 3) at time t [s] (the identity without `rotation`)."""
        if self.rotation is None:
            return np.eye(3)
        return rotation_matrix(f"MeshCollider.rotation({t})", self.rotation(t))

    def placed(self, t: float) -> MeshCollider:
        """The mesh turned and moved to where it is at time t [s], standing still."""
        if self.path is None and self.rotation is None:
            return self
        centre = self.centre
        vertices = (self.mesh.vertices - centre) @ self.turn(t).T + centre + self.offset(t)
        return replace(self, mesh=Mesh(vertices, self.mesh.triangles), path=None, rotation=None)

    def carried(self, points, t):
        centre, turn = self.centre, self.turn(t) @ self.turn(0.0).T
        return (points - centre - self.offset(0.0)) @ turn.T + centre + self.offset(t)

    def moved(self, offset):
        return replace(self, mesh=Mesh(self.mesh.vertices + offset, self.mesh.triangles), path=None)

    def bounds(self):
        return np.array([self.mesh.vertices.min(axis=0), self.mesh.vertices.max(axis=0)])

    def packed(self):
        return MESH, self.centre, np.zeros(3), 0.0


def rotation_matrix(name: str, value) -> np.ndarray:
    """A rotation vector (3,) [rad] or a 3x3 rotation matrix as a 3x3 matrix."""
    array = np.asarray(value, dtype=np.float64) if np.ndim(value) else None
    require(array is not None and array.shape in ((3,), (3, 3)), name, value,
            "a rotation vector (axis x angle [rad], 3 numbers) or a 3x3 rotation matrix")
    array = as_array(name, array, np.float64, array.shape)
    if array.shape == (3,):
        from scipy.spatial.transform import Rotation
        return Rotation.from_rotvec(array).as_matrix()
    require(np.abs(array @ array.T - np.eye(3)).max() < ROTATION_TOLERANCE
            and np.linalg.det(array) > 0, name, array.tolist(),
            "a rotation matrix (orthonormal, determinant +1)")
    return array


def closed(mesh: Mesh) -> bool:
    """Whether every edge of the mesh, its vertices at equal positions merged, belongs to
    exactly two triangles (a closed surface: it has an inside)."""
    _, merged = np.unique(mesh.vertices, axis=0, return_inverse=True)
    triangles = merged.ravel()[mesh.triangles]
    ordered = np.sort(triangles, axis=1)
    proper = (ordered[:, 1:] != ordered[:, :-1]).all(axis=1)
    _, uses = unique_rows(triangle_edges(triangles[proper]), return_counts=True)
    return bool(len(uses)) and bool((uses == 2).all())
