"""A deforming triangle mesh as a collider: a walking figure, a breathing chest, a skinned
character exported from Blender as a point cache.

Its triangles stay; its vertices move: `motion` gives them at any time, as a callable or as
samples at a frame rate. The collision stage (animated_contact.py) sweeps every triangle
over each step and keeps particles on the side they started, thickness away, with the same
Coulomb friction as every collider (colliders.py), measured against the surface point's own
velocity.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ...body.mesh import Mesh, triangle_edges, unique_rows
from ...inputs import limits
from ...inputs.validation import as_array, in_range, require
from .animation_files import read_animation
from .mesh_collider import closed
from .sdf import INSIDE
from .shapes import ANIMATED, Collider


@dataclass(frozen=True, kw_only=True)
class AnimatedMeshCollider(Collider):
    """The triangles of `mesh` [m], their vertices moving as `motion` says.

    motion: a callable t [s] -> vertex positions (V, 3) [m], V the mesh's vertex count, or an
        array (samples, V, 3) [m] of positions sampled at `fps` from t = 0 (linear in
        between, held at the last sample after it). None: the mesh stands still as given.
    fps: samples per second of an array `motion` (required with one, not allowed otherwise).
    The mesh's own vertices are its positions at t = 0 when `motion` is None or a callable
    (a callable's value at 0 is what the collider is at 0; the mesh gives the triangles).

    Particles are kept `thickness` [m] away on the side of each triangle they were on at the
    step's start, whatever the triangle does in the step (continuous collision); a closed
    mesh (every edge shared by two triangles) also reports distances signed negative inside
    (Simulation.collider_distance). `path` is not taken: the motion says everything.

    edge_contact: which of the body's edges the cloth's edges are kept thickness away from,
    so that a sharp edge cannot pass between two particles (animated_edges.py). "auto" (the
    default): the edges sharp enough to pass through a cloth edge whose particles are kept
    out, those whose faces turn by more than 2 asin(2 thickness / (1.25 x the cloth's longest
    rest edge)) in any sample (a callable's body: at t = 0); True: every edge; False: none.
    """

    mesh: Mesh = field(kw_only=False)
    motion: Callable[[float], object] | np.ndarray | None = field(default=None,
                                                                  kw_only=False)
    fps: float | None = None
    edge_contact: bool | str = "auto"

    def __post_init__(self):
        super().__post_init__()
        name = "AnimatedMeshCollider"
        require(self.edge_contact is True or self.edge_contact is False
                or self.edge_contact == "auto", f"{name}.edge_contact", self.edge_contact,
                '"auto", True or False')
        require(self.path is None, f"{name}.path", self.path,
                "None (the motion moves an animated mesh: give its vertices at every time)")
        mesh = self.mesh
        require(isinstance(mesh, Mesh) and mesh.triangle_count > 0, f"{name}.mesh", mesh,
                "a Mesh with at least one triangle")
        vertices = mesh.vertex_count
        if callable(self.motion):
            require(self.fps is None, f"{name}.fps", self.fps,
                    "None with a callable motion (it is called at every step's time)")
            self.vertices_at(0.0)
        elif self.motion is not None:
            try:
                if np.iscomplexobj(self.motion):
                    raise TypeError("complex")
                motion = np.asarray(self.motion, dtype=np.float64)
            except (TypeError, ValueError, OverflowError):
                raise ValueError(f"{name}.motion must be None, a callable t -> (V, 3) or an "
                                 f"array (samples, {vertices}, 3) of real numbers, got "
                                 f"{self.motion!r:.80}") from None
            require(motion.ndim == 3 and motion.shape[1:] == (vertices, 3),
                    f"{name}.motion.shape", getattr(motion, "shape", None),
                    f"(samples, {vertices}, 3): a position for each of the mesh's {vertices} "
                    "vertices in every sample")
            require(0 < motion.size <= limits.MOTION_VALUES, f"{name}.motion.size", motion.size,
                    f"at least one sample and at most {limits.MOTION_VALUES} numbers")
            motion = as_array(f"{name}.motion", motion, np.float64, (None, vertices, 3))
            bad = np.argwhere(np.abs(motion) > limits.COORDINATE.high)
            require(len(bad) == 0, f"{name}.motion[{', '.join(map(str, bad[0])) if len(bad) else ''}]",
                    motion[tuple(bad[0])] if len(bad) else None,
                    f"a coordinate {limits.COORDINATE.text()}")
            motion.setflags(write=False)
            object.__setattr__(self, "motion", motion)
            object.__setattr__(self, "fps", in_range(f"{name}.fps", self.fps, limits.FPS))
            collapsed = _collapsed(mesh.triangles, motion)
            require(len(collapsed) == 0, f"{name}.motion[{collapsed[0] if len(collapsed) else 0}]",
                    "a mesh collapsed to no area (its vertices on a point or a line)",
                    "a surface in every sample")
        else:
            require(self.fps is None, f"{name}.fps", self.fps, "None without a motion")

    @classmethod
    def load(cls, path, rest=None, fps: float | None = None, prim: str | None = None,
             **options) -> AnimatedMeshCollider:
        """The animated mesh of a file: an npz (`triangles`, `positions`, `fps`), a PC2 cache
        with its `rest` mesh file, an OBJ sequence ("walk_*.obj", ordered by the number in
        the names) or a USD stage (a Mesh prim's time-sampled points, `prim` choosing among
        several); `fps` is required for PC2 and OBJ sequences and replaces an npz's or USD
        stage's own rate (animation_files.py). options: thickness and friction."""
        mesh, samples, fps = read_animation(path, rest, fps, prim)
        return cls(mesh, samples, fps=fps, **options)

    @property
    def sampled(self) -> bool:
        """Whether the motion is an array of samples (else a callable or none)."""
        return isinstance(self.motion, np.ndarray)

    @cached_property
    def edge_turning(self) -> tuple[np.ndarray, np.ndarray]:
        """(edges (E, 2) as sorted vertex pairs, the largest angle [rad] between the normals
        of two triangles on each, over the samples (a callable's or a still body's: at t = 0);
        pi on an open mesh's rim, where one triangle ends like a blade)."""
        triangles = self.mesh.triangles
        edges, index = unique_rows(triangle_edges(triangles), return_inverse=True)
        index = index.ravel()
        shapes = self.motion if self.sampled else [self.vertices_at(0.0)]
        turning = np.zeros(len(edges))
        uses = np.bincount(index, minlength=len(edges))
        turning[uses == 1] = np.pi
        order = np.argsort(index, kind="stable")
        first = order[np.r_[0, np.flatnonzero(np.diff(index[order])) + 1]]
        for vertices in shapes:
            corners = vertices[triangles]
            normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
            per_side = np.repeat(normal, 3, axis=0)           # the normal beside each edge use
            reference = per_side[first][index]                # the edge's first triangle's
            angle = np.arccos(np.clip(np.sum(per_side * reference, axis=1), -1.0, 1.0))
            np.maximum.at(turning, index, angle)
        return edges, turning

    @property
    def closed(self) -> bool:
        """Whether the mesh is closed (every edge shared by two triangles): it has an inside."""
        return closed(self.mesh)

    def vertices_at(self, t: float) -> np.ndarray:
        """The vertex positions (V, 3) [m] at time t [s]."""
        if self.motion is None:
            return self.mesh.vertices
        if self.sampled:
            return interpolate(self.motion, self.fps, t)
        name = f"AnimatedMeshCollider.motion({t})"
        vertices = as_array(name, self.motion(t), np.float64, (self.mesh.vertex_count, 3))
        bad = np.argwhere(np.abs(vertices) > limits.COORDINATE.high)
        require(len(bad) == 0, f"{name}[{', '.join(map(str, bad[0])) if len(bad) else ''}]",
                vertices[tuple(bad[0])] if len(bad) else None,
                f"a coordinate {limits.COORDINATE.text()}")
        return vertices

    def inside(self, points, t: float) -> np.ndarray:
        """(P,) bool: which of the points (P, 3) [m] are inside the closed mesh as it is at
        time t [s] (libigl's fast winding number above 1/2): a check of a run's frames (a
        garment demo's "particles inside the figure")."""
        import igl

        require(self.closed, "AnimatedMeshCollider.inside", "an open mesh",
                "a closed mesh (every edge on two triangles): an open one has no inside")
        points = as_array("points", points, np.float64, (None, 3))
        winding = igl.fast_winding_number(self.vertices_at(t).astype(np.float64),
                                          self.mesh.triangles.astype(np.int64), points)
        return np.abs(winding) > INSIDE

    def placed(self, t: float) -> AnimatedMeshCollider:
        """The mesh as it is at time t [s], standing still."""
        if self.motion is None:
            return self
        return replace(self, mesh=Mesh(self.vertices_at(t), self.mesh.triangles), motion=None,
                       fps=None)

    def carried(self, points, t):
        raise TypeError("an animated mesh carries points by its triangles, not rigidly: "
                        "tc.Attachment binds them to it")

    def moved(self, offset):
        return replace(self, mesh=Mesh(self.vertices_at(0.0) + offset, self.mesh.triangles),
                       motion=None, fps=None)

    def bounds(self):
        """Over every sample of a sampled motion (a callable's: its mesh at t = 0)."""
        vertices = self.motion if self.sampled else self.mesh.vertices[None]
        return np.array([vertices.min(axis=(0, 1)), vertices.max(axis=(0, 1))])

    def packed(self):
        return ANIMATED, np.zeros(3), np.zeros(3), 0.0


def _collapsed(triangles: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """The samples (S, V, 3) whose triangles have no area left, against the largest."""
    a, b, c = (samples[:, triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1).sum(axis=1)
    return np.flatnonzero(area <= 1e-12 * max(float(area.max()), 1e-300))


def interpolate(samples: np.ndarray, fps: float, t: float) -> np.ndarray:
    """Positions at time t [s] of samples (S, V, 3) taken at `fps` from t = 0: linear between
    the two samples around t, the last one after it (the kernels' rule: animated_bodies.py)."""
    s = max(t, 0.0) * fps
    first = min(int(np.floor(s)), len(samples) - 1)
    if first == len(samples) - 1:
        return samples[first]
    frac = s - first
    return samples[first] + frac * (samples[first + 1] - samples[first])

