"""Model: the fixed description of a body as Taichi fields, built once from a Cloth."""

from __future__ import annotations

import hashlib

import numpy as np
import taichi as ti

from .body.bending_curve import curve_tables
from .body.material import SpringKind
from .body.mesh import triangle_edges, unique_rows
from .body.topology import Cloth, color_neighbours, color_springs
from .energies.bending import bending_stencils, tangents, weld_groups
from .energies.isometric import is_flat, isometric_matrix
from .inputs.validation import require
from .runtime import backend
from .runtime.transfer import upload
from .state import State


@backend.kernel_argument
class Model:
    """Masses, springs and per-particle spring adjacency of one cloth (load()), read-only to
    every kernel. A Simulation's model is lent by pool.py and loaded again for the next
    simulation of its structure once that one is collected.

    particle_mass         [kg], shape (particle_count,)
    particle_inv_mass     [1/kg]; 0 for pinned particles (lecture: "set 1/m to zero")
    particle_rest_position [m]
    spring_indices        (i, j) per spring, shape (spring_count,)
    spring_rest_length    [m]
    spring_stiffness      [N/m]
    spring_damping        [kg/s]
    spring_kind           SpringKind value
    particle_spring_start CSR offsets, shape (particle_count + 1,): particle i's springs are
                          adjacency_spring[start[i]:start[i + 1]], their other ends adjacency_other;
                          forces are gathered per particle in this fixed order (deterministic,
                          no float atomics)
    particle_spring_split i is the second end of its springs in [start[i], split[i]) and the
                          first end in [split[i], start[i + 1]), so a gather knows each sign
    altitude_indices      [p, a, b, c] per altitude spring (Selle et al. 2008; topology.py),
                          shape (altitude_count,); altitude_rest_length [m],
                          altitude_stiffness [N/m], altitude_damping [kg/s]
    particle_altitude_start CSR offsets, shape (particle_count + 1,): particle i is corner
                          adjacency_altitude[a] % 4 of altitude spring adjacency_altitude[a] // 4
                          for a in [start[i], start[i + 1]), in increasing order (the gather's)
    face_indices, face_gradient (grad lambda_1, grad lambda_2 as x1 y1 x2 y2), face_area,
    face_moduli, face_damping, face_bending (00 11 22 01 02 12), face_hinge: a Fabric's
                          triangles (Cloth's arrays of those names; energies/);
                          face_compression, with `softened`, Cloth's;
                          face_edge_rest the rest length of each one's edge i (opposite
                          corner i) [m], for tearing
    hinge_indices, hinge_faces, hinge_rest_tangent (tan of half the rest angle, continued as
                          energies/bending.tangents): its hinges
    particle_weld         each particle's representative among those its seams sew together
                          (Cloth.particle_weld), read where `sewn`: a hinge across a seam
    weld_start, weld_member: the groups of particles sewn together (two or more), a CSR,
                          the representative first: the implicit solve moves each group as
                          one particle (integrators/conjugate_gradients.py)
    particle_face_start, adjacency_face: particle i is corner adjacency_face[a] % 3 of
                          triangle adjacency_face[a] // 3 (CSR, as for altitude springs);
    particle_hinge_start, adjacency_hinge: the same for hinges (4 corners)
    face_components, face_curve: with `curved`, each triangle's b (00..22 as 3 d + i) and its
                          BendingCurve (-1: none), whose law (energies/bending_law.py) reads
                          curve_samples [1/m], curve_rigidity, curve_slope, curve_integral
                          (body/bending_curve.curve_tables), curve_length samples each,
                          curve c's sample j at c curve_length + j
    particle_bend_start, bend_other, bend_stiffness, bend_damping: with `isometric` (a flat
                          rest sheet), the bending of energies/isometric.isometric_matrix, a CSR
                          of each particle's neighbours, gathered in increasing order; the
                          hinges' angles are then not computed (XPBD takes its rows too)

    Python attributes read at compile time (fixed for the model's life):
    particle_count, spring_count, altitude_count, face_count, hinge_count, relative_damping,
    isometric, sewn (the cloth has seams), weld_count (its groups of particles sewn
    together), curved (Cloth.curved), curve_count, curve_length, softened (Cloth.softened).
    """

    def __init__(self, cloth: Cloth, pinned: np.ndarray | None = None, isometric: bool = False):
        real = backend.real()
        self.particle_count = n = cloth.particle_count
        self.spring_count = s = cloth.spring_count
        self.altitude_count = a = cloth.altitude_count
        self.face_count = faces = cloth.face_count
        self.hinge_count = hinges = cloth.hinge_count
        self.relative_damping = cloth.damping == "relative"
        require(not isometric or is_flat(cloth), "isometric", isometric,
                "False for a body whose rest sheet is not flat (energies/isometric.is_flat)")
        self.isometric = bool(isometric)
        self.sewn = bool(len(cloth.seam_indices))
        weld_start, weld_member = weld_groups(cloth.particle_weld)
        self.weld_count = len(weld_start) - 1
        self.curved = cloth.curved
        self.softened = cloth.softened
        self.curve_count = len(cloth.bending_curves) if self.curved else 0
        self.curve_length = _curve_length(cloth) if self.curved else 1
        require(not (self.curved and isometric), "isometric", isometric,
                "False for a body whose bending depends on curvature (a BendingCurve)")
        bends = len(self._isometric_bending(cloth)[1]) if self.isometric else 0
        fields = backend.FieldGroup()
        s1 = max(s, 1)
        self.particle_mass = fields.scalar(real, n)
        self.particle_inv_mass = fields.scalar(real, n)
        self.particle_rest_position = fields.vector(3, real, n)
        self.spring_indices = fields.vector(2, ti.i32, s1)
        self.spring_rest_length = fields.scalar(real, s1)
        self.spring_stiffness = fields.scalar(real, s1)
        self.spring_damping = fields.scalar(real, s1)
        self.spring_kind = fields.scalar(ti.i32, s1)
        self.particle_spring_start = fields.scalar(ti.i32, n + 1)
        self.particle_spring_split = fields.scalar(ti.i32, n)
        self.adjacency_spring = fields.scalar(ti.i32, max(2 * s, 1))
        self.adjacency_other = fields.scalar(ti.i32, max(2 * s, 1))
        self.altitude_indices = fields.vector(4, ti.i32, max(a, 1))
        self.altitude_rest_length = fields.scalar(real, max(a, 1))
        self.altitude_stiffness = fields.scalar(real, max(a, 1))
        self.altitude_damping = fields.scalar(real, max(a, 1))
        self.particle_altitude_start = fields.scalar(ti.i32, n + 1)
        self.adjacency_altitude = fields.scalar(ti.i32, max(4 * a, 1))
        f1, h1 = max(faces, 1), max(hinges, 1)
        self.face_indices = fields.vector(3, ti.i32, f1)
        self.face_gradient = fields.vector(4, real, f1)
        self.face_area = fields.scalar(real, f1)
        self.face_moduli = fields.vector(4, real, f1)
        self.face_damping = fields.scalar(real, f1)
        self.face_bending = fields.vector(6, real, f1)
        self.face_hinge = fields.vector(3, ti.i32, f1)
        self.face_edge_rest = fields.vector(3, real, f1)
        self.hinge_indices = fields.vector(4, ti.i32, h1)
        self.hinge_faces = fields.vector(2, ti.i32, h1)
        self.hinge_rest_tangent = fields.scalar(real, h1)
        self.particle_weld = fields.scalar(ti.i32, n)
        self.weld_start = fields.scalar(ti.i32, self.weld_count + 1)
        self.weld_member = fields.scalar(ti.i32, max(len(weld_member), 1))
        self.particle_face_start = fields.scalar(ti.i32, n + 1)
        self.adjacency_face = fields.scalar(ti.i32, 3 * f1)
        self.particle_hinge_start = fields.scalar(ti.i32, n + 1)
        self.adjacency_hinge = fields.scalar(ti.i32, 4 * h1)
        self.particle_bend_start = fields.scalar(ti.i32, n + 1)
        self.bend_other = fields.scalar(ti.i32, max(bends, 1))
        self.bend_stiffness = fields.scalar(real, max(bends, 1))
        self.bend_damping = fields.scalar(real, max(bends, 1))
        self.face_compression = fields.scalar(real, f1 if self.softened else 1)
        curved_faces = f1 if self.curved else 1
        self.face_components = fields.vector(9, real, curved_faces)
        self.face_curve = fields.scalar(ti.i32, curved_faces)
        curves = max(self.curve_count, 1) * self.curve_length      # curve c's sample j at c N + j
        self.curve_samples = fields.scalar(real, curves)
        self.curve_rigidity = fields.vector(3, real, curves)
        self.curve_slope = fields.vector(3, real, curves)
        self.curve_integral = fields.vector(3, real, curves)
        fields.finalize(self)
        self._colouring = None
        self._altitude_colouring = None
        self._element_colourings = None
        self._edge_colouring = None
        self.load(cloth, pinned)

    @staticmethod
    def structure(cloth: Cloth, pinned: np.ndarray | None = None,
                  isometric: bool = False) -> tuple:
        """What the kernels of a Model of `cloth` read at compile time, and the topology its
        adjacency and colouring come from: Models of equal structure are interchangeable once
        load() has put a cloth's values in (pool.py reuses them)."""
        digest = hashlib.blake2b(digest_size=16)
        digest.update(np.ascontiguousarray(cloth.spring_indices).tobytes())
        digest.update(np.ascontiguousarray(cloth.altitude_indices).tobytes())
        digest.update(np.ascontiguousarray(cloth.face_indices).tobytes())
        digest.update(np.ascontiguousarray(cloth.hinge_indices).tobytes())
        return ("Model", cloth.particle_count, cloth.spring_count, cloth.altitude_count,
                cloth.face_count, cloth.hinge_count, cloth.damping == "relative",
                bool(isometric), bool(len(cloth.seam_indices)), cloth.curved, cloth.softened,
                len(cloth.bending_curves) if cloth.curved else 0,
                _curve_length(cloth) if cloth.curved else 1,
                *(len(a) for a in weld_groups(cloth.particle_weld)), digest.hexdigest())

    def load(self, cloth: Cloth, pinned: np.ndarray | None = None,
             isometric: bool = False) -> None:
        """Upload `cloth` (of this model's structure, `isometric` included: the structure
        holds it) with `pinned` (default: the cloth's)."""
        self.cloth = cloth
        if self._colouring is not None:
            self._colouring.pack(cloth)
        if self._edge_colouring is not None:
            self._edge_colouring.pack(FaceEdges(cloth))
        self.pinned = cloth.pinned if pinned is None else np.asarray(pinned, bool)
        inv_mass = inverse_masses(cloth.particle_mass, self.pinned)
        n, s = self.particle_count, self.spring_count
        ends = cloth.spring_indices
        owner = np.concatenate([ends[:, 0], ends[:, 1]])
        other = np.concatenate([ends[:, 1], ends[:, 0]])
        spring = np.concatenate([np.arange(s), np.arange(s)])
        first_end = np.repeat([1, 0], s)
        order = np.lexsort((other, first_end, owner))
        start = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n))])
        split = start[:-1] + np.bincount(ends[:, 1], minlength=n)
        altitude_start, altitude_order = corner_adjacency(cloth.altitude_indices, n)
        face_start, face_order = corner_adjacency(cloth.face_indices, n)
        hinge_start, hinge_order = corner_adjacency(cloth.hinge_indices, n)
        bending = cloth.face_bending[:, [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
        if self.isometric:
            bend_start, *bends = self._isometric_bending(cloth)
            self._isometric_of = (None,)
            self._bend_rows = (bend_start, bends[0])      # for XPBD's colouring of particles
            upload(((self.particle_bend_start, bend_start),
                    *zip((self.bend_other, self.bend_stiffness, self.bend_damping), bends)))
        if self.softened:
            upload(((self.face_compression, cloth.face_compression),))
        if self.curved:
            upload(((self.face_components, cloth.face_components.reshape(-1, 9)),
                    (self.face_curve, cloth.face_curve),
                    *zip((self.curve_samples, self.curve_rigidity, self.curve_slope,
                          self.curve_integral),
                         (t.reshape(len(t) * self.curve_length, *t.shape[2:])
                          for t in curve_tables(cloth.bending_curves, self.curve_length)))))
        upload(((self.particle_mass, cloth.particle_mass),
                (self.particle_inv_mass, inv_mass),
                (self.particle_rest_position, cloth.particle_position),
                (self.spring_indices, cloth.spring_indices),
                (self.spring_rest_length, cloth.spring_rest_length),
                (self.spring_stiffness, cloth.spring_stiffness),
                (self.spring_damping, cloth.spring_damping),
                (self.spring_kind, cloth.spring_kind),
                (self.particle_spring_start, start),
                (self.particle_spring_split, split),
                (self.adjacency_spring, spring[order]),
                (self.adjacency_other, other[order]),
                (self.altitude_indices, cloth.altitude_indices),
                (self.altitude_rest_length, cloth.altitude_rest_length),
                (self.altitude_stiffness, cloth.altitude_stiffness),
                (self.altitude_damping, cloth.altitude_damping),
                (self.particle_altitude_start, altitude_start),
                (self.adjacency_altitude, altitude_order),
                (self.face_indices, cloth.face_indices),
                (self.face_gradient, cloth.face_gradient[:, 1:].reshape(-1, 4)),
                (self.face_area, cloth.face_area),
                (self.face_moduli, cloth.face_moduli),
                (self.face_damping, cloth.face_damping),
                (self.face_bending, bending),
                (self.face_hinge, cloth.face_hinge),
                (self.face_edge_rest, face_edges(cloth)),
                (self.hinge_indices, cloth.hinge_indices),
                (self.hinge_faces, cloth.hinge_faces),
                (self.hinge_rest_tangent, tangents(cloth.hinge_rest_angle)),
                (self.particle_weld, cloth.particle_weld),
                *zip((self.weld_start, self.weld_member), weld_groups(cloth.particle_weld)),
                (self.particle_face_start, face_start),
                (self.adjacency_face, face_order),
                (self.particle_hinge_start, hinge_start),
                (self.adjacency_hinge, hinge_order)))

    def _isometric_bending(self, cloth: Cloth) -> tuple:
        """isometric_matrix of `cloth`, computed once for a cloth both built and loaded (its
        sizes make the fields, its values are what load() uploads)."""
        if getattr(self, "_isometric_of", (None,))[0] is not cloth:
            self._isometric_of = (cloth, isometric_matrix(cloth))
        return self._isometric_of[1]

    def set_pinned(self, pinned: np.ndarray) -> None:
        """Pin exactly `pinned` (N,) bool from the next step on: inverse masses 0 there and
        1/m elsewhere (handles holding and letting go)."""
        self.pinned = np.asarray(pinned, bool)
        upload(((self.particle_inv_mass, inverse_masses(self.cloth.particle_mass, self.pinned)),))

    def state(self, position_limit: float = 1e6) -> State:
        """A fresh State at the rest configuration, at rest, with every spring intact, whose
        divergence guard flags any |coordinate| beyond position_limit [m]."""
        state = State(self.particle_count, self.spring_count, position_limit, self.altitude_count,
                      self.face_count, self.hinge_count)
        state.reset(self.cloth.particle_position)
        return state

    def spring_colouring(self) -> SpringColouring:
        """The springs grouped so that no two in a colour share a particle; built on first use
        (only position-based passes need it)."""
        if self._colouring is None:
            self._colouring = SpringColouring(*color_springs(self.cloth.spring_indices,
                                                             self.particle_count), self.cloth)
        return self._colouring

    def altitude_colouring(self) -> SpringColouring:
        """The altitude springs grouped so that no two in a colour share a particle (position-
        based passes; the spring colouring when there are none, never read then)."""
        if self.altitude_count == 0:
            return self.spring_colouring()
        if self._altitude_colouring is None:
            self._altitude_colouring = SpringColouring(*color_springs(
                self.cloth.altitude_indices, self.particle_count))
        return self._altitude_colouring

    def element_colourings(self) -> tuple[SpringColouring, SpringColouring]:
        """(membranes, bending): a Fabric's triangles grouped so that no two in a colour share
        a particle, by their corners; and its bending's, for position-based passes: the
        triangles by the particles their mid-edge bending moves
        (energies/bending.bending_stencils), or with `isometric` the particles, no two in a
        colour coupled by the bending's matrix (energies/isometric.py: a pass per particle)."""
        if self._element_colourings is None:
            if self.isometric:
                bending = SpringColouring(*color_neighbours(*self._bend_rows))
            else:
                bending = SpringColouring(*color_springs(bending_stencils(self.cloth),
                                                         self.particle_count))
            self._element_colourings = (
                SpringColouring(*color_springs(self.cloth.face_indices, self.particle_count)),
                bending)
        return self._element_colourings


    def edge_colouring(self) -> SpringColouring:
        """A Fabric's triangle edges as stretch springs of zero stiffness (FaceEdges), grouped
        so that no two in a colour share a particle: what strain limiting relaxes on a body
        without springs."""
        if self._edge_colouring is None:
            edges = FaceEdges(self.cloth)
            self._edge_colouring = SpringColouring(*color_springs(edges.spring_indices,
                                                                  self.particle_count), edges)
        return self._edge_colouring


class FaceEdges:
    """The edges of a cloth's Fabric triangles in the shape of its springs (spring_indices,
    rest lengths at the rest positions, kind STRETCH, no stiffness or damping), for the
    position-based passes that act on springs (strain limiting)."""

    def __init__(self, cloth: Cloth):
        self.spring_indices = unique_rows(triangle_edges(cloth.face_indices)).reshape(-1, 2)
        x = cloth.rest_position
        self.spring_rest_length = np.linalg.norm(x[self.spring_indices[:, 0]]
                                                 - x[self.spring_indices[:, 1]], axis=1)
        count = len(self.spring_indices)
        self.spring_stiffness = np.zeros(count)
        self.spring_damping = np.zeros(count)
        self.spring_kind = np.full(count, int(SpringKind.STRETCH))


def face_edges(cloth: Cloth) -> np.ndarray:
    """(F, 3): the rest length of each Fabric triangle's edge i (opposite corner i) [m]."""
    x, corners = cloth.rest_position, cloth.face_indices
    return np.stack([np.linalg.norm(x[corners[:, (i + 1) % 3]] - x[corners[:, (i + 2) % 3]],
                                    axis=1) for i in range(3)], 1) if len(corners) else np.zeros((0, 3))


def corner_adjacency(indices: np.ndarray, particle_count: int) -> tuple[np.ndarray, np.ndarray]:
    """(start (N + 1,), order): the CSR of elements with k corners each ((E, k) particle
    indices): particle i is corner order[a] % k of element order[a] // k for a in
    [start[i], start[i + 1]), by element, then corner (the gathers' fixed order)."""
    corners = indices.ravel()
    order = np.argsort(corners, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(corners, minlength=particle_count))])
    return start, order


def inverse_masses(mass: np.ndarray, pinned: np.ndarray) -> np.ndarray:
    """1/m per particle, 0 where pinned (lecture: "set 1/m to zero")."""
    return np.where(pinned, 0.0, 1.0 / np.where(mass > 0, mass, 1.0))


@backend.kernel_argument
class SpringColouring:
    """Springs by colour: colour c is springs order[start[c]:start[c + 1]] (fields, read in
    loops whose bounds are not compile-time constants, so a kernel visiting every colour
    compiles one copy of its loop body); count: how many colours (a Python int).

    With `springs` (a Cloth), the springs' ends, rest lengths, stiffnesses, dampings and
    kinds are also kept in that order (position t holds spring order[t]): a pass then reads
    them front to back instead of gathering through `order` (faster per projection:
    docs/performance.md); pack() refreshes them when the Model is loaded with another
    cloth."""

    def __init__(self, order, offsets, springs=None):
        self.count = len(offsets) - 1
        self.offsets = tuple(int(o) for o in offsets)
        self.packed = springs is not None
        size = max(len(order), 1)
        fields = backend.FieldGroup()
        self.order = fields.scalar(ti.i32, size)
        self.start = fields.scalar(ti.i32, len(offsets))
        if self.packed:
            real = backend.real()
            self.ends = fields.vector(2, ti.i32, size)
            self.rest = fields.scalar(real, size)
            self.stiffness = fields.scalar(real, size)
            self.damping = fields.scalar(real, size)
            self.kind = fields.scalar(ti.i32, size)
        fields.finalize(self)
        self._order = np.asarray(order)
        upload(((self.order, order), (self.start, offsets)))
        if self.packed:
            self.pack(springs)

    def pack(self, cloth) -> None:
        """Copy `cloth`'s spring values into colour order."""
        order = self._order
        upload(((self.ends, cloth.spring_indices[order]),
                (self.rest, cloth.spring_rest_length[order]),
                (self.stiffness, cloth.spring_stiffness[order]),
                (self.damping, cloth.spring_damping[order]),
                (self.kind, cloth.spring_kind[order])))


def _curve_length(cloth: Cloth) -> int:
    """The most samples of the cloth's bending curves (each is padded to it)."""
    return max(len(c.curvature) for c in cloth.bending_curves)
