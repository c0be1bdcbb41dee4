"""Host-side topology (numpy): springs by kind with rest lengths, lumped masses, pins -> Cloth.

Spring rules
------------
* Grid meshes (`Mesh.grid_shape` set) follow Stuyck fig. 4.2 exactly: stretch springs between
  axis neighbours, shear springs on both diagonals of every quad, bend springs between 2-ring
  neighbours along each axis (skipping the particle in between).
* Any other triangle mesh: a stretch spring on every edge, and a bend spring between the two
  vertices opposite each interior edge (an edge shared by exactly two triangles). Edges on
  three or more triangles get no bend spring. There are no shear springs: on a general
  triangulation the edges already resist shear.
* Explicit springs: "it is totally up to you which particles you connect" (Stuyck 4.3); pass
  `springs=` as an (S, 2) index array (all stretch) or a mapping {kind: (S, 2) array}.

Generated springs never repeat a particle pair; where two rules give the same pair the first
kind in STRETCH, SHEAR, BEND order keeps it. Explicit springs that repeat a pair are rejected.
Rest lengths are distances in the reference configuration.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Mapping

import numpy as np

from ..energies.altitude import altitude_springs
from ..energies.bending import (bending_matrices, curvature_components, dihedral_angles, hinges,
                                second_edge, welded)
from ..energies.membrane import material_frames
from ..inputs.validation import as_array, finite_number, require
from .fabric import Fabric
from .material import Material, SpringKind, SpringParams
from .mesh import Mesh, nonmanifold, triangle_edges, unique_rows, uv_warp


def grid_springs(rows: int, cols: int) -> dict[SpringKind, np.ndarray]:
    """Stuyck fig. 4.2 springs of a row-major rows x cols grid, as {kind: (S, 2) int64}.

    Counts: stretch rows(cols-1) + cols(rows-1); shear 2(rows-1)(cols-1);
    bend rows(cols-2) + cols(rows-2) (each term 0 when the grid is too small).
    """
    index = np.arange(rows * cols).reshape(rows, cols)

    def pairs(a, b):
        return np.stack([a.ravel(), b.ravel()], axis=1)

    return {
        SpringKind.STRETCH: np.concatenate([pairs(index[:, :-1], index[:, 1:]),
                                            pairs(index[:-1, :], index[1:, :])]),
        SpringKind.SHEAR: np.concatenate([pairs(index[:-1, :-1], index[1:, 1:]),
                                          pairs(index[:-1, 1:], index[1:, :-1])]),
        SpringKind.BEND: np.concatenate([pairs(index[:, :-2], index[:, 2:]),
                                         pairs(index[:-2, :], index[2:, :])]),
    }


def mesh_springs(triangles: np.ndarray) -> dict[SpringKind, np.ndarray]:
    """Stretch springs on every edge and bend springs across every interior edge."""
    directed = triangle_edges(triangles)
    opposite = triangles[:, [2, 0, 1]].ravel()
    edges, inverse, counts = unique_rows(directed, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    interior = np.flatnonzero(counts == 2)
    bend = np.stack([opposite[order[starts[interior]]], opposite[order[starts[interior] + 1]]], axis=1)
    return {SpringKind.STRETCH: edges, SpringKind.BEND: bend}


def unique_springs(springs: Mapping[SpringKind, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Merge springs by kind into (indices (S, 2) with i < j, kind (S,)), dropping repeated
    pairs (the lower kind wins) and pairs that join a particle to itself."""
    kinds = sorted(springs)
    pairs = np.concatenate([np.sort(np.asarray(springs[k], np.int64).reshape(-1, 2), axis=1)
                            for k in kinds])
    kind = np.concatenate([np.full(len(springs[k]), int(k), np.int64) for k in kinds])
    keep = pairs[:, 0] != pairs[:, 1]
    pairs, kind = pairs[keep], kind[keep]
    _, first = unique_rows(pairs, return_index=True)
    first = np.sort(first)
    return pairs[first].reshape(-1, 2), kind[first]


def lumped_masses(vertices: np.ndarray, triangles: np.ndarray, density: float) -> np.ndarray:
    """Stuyck 4.2: each triangle's rest area x density, one third to each corner [kg].

    Raises ValueError for a triangle of zero area, which would carry no mass.
    """
    p = vertices[triangles]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    longest = np.max(np.linalg.norm(p - p[:, [1, 2, 0]], axis=2), axis=1)
    degenerate = np.flatnonzero(area <= 1e-12 * longest ** 2)
    if len(degenerate):
        t = int(degenerate[0])
        raise ValueError(f"triangles[{t}] (vertices {triangles[t].tolist()}) must have an area > 0 m^2, "
                         f"got {area[t]:.3g} m^2 ({len(degenerate)} degenerate triangle(s) in total); "
                         "remove degenerate triangles before building a cloth")
    return np.bincount(triangles.ravel(), weights=np.repeat(area * density / 3.0, 3),
                       minlength=len(vertices))


def color_springs(indices: np.ndarray, particle_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Partition springs (or any elements: rows of particle indices, (E, k)) into colours in
    which no two share a particle.

    Returns (order, offsets): elements order[offsets[c]:offsets[c + 1]] form colour c, by
    lowest particle index. Each colour is a maximal independent set grown by deterministic
    random priorities, so elements
    of one colour can be relaxed in parallel with Gauss-Seidel semantics (lecture:
    "relaxation").
    """
    indices = np.asarray(indices)
    indices = indices.reshape(len(indices), -1) if indices.size else indices.reshape(0, 2)
    rng = np.random.default_rng(0)
    priority = rng.permutation(len(indices))
    colour = np.full(len(indices), -1)
    remaining = np.arange(len(indices))
    offsets = [0]
    while remaining.size:
        taken = np.zeros(particle_count, bool)
        candidates = remaining
        while candidates.size:
            ends = indices[candidates]
            best = np.full(particle_count, -1)
            for column in ends.T:
                np.maximum.at(best, column, priority[candidates])
            won = (best[ends] == priority[candidates][:, None]).all(axis=1)
            colour[candidates[won]] = len(offsets) - 1
            taken[ends[won].ravel()] = True
            candidates = candidates[~won]
            candidates = candidates[~taken[indices[candidates]].any(axis=1)]
        remaining = remaining[colour[remaining] < 0]
        offsets.append(len(indices) - len(remaining))
    # Within a colour, by lowest particle index: the elements of a colour share no particle,
    # so their order does not change a pass's result, and sorted they touch memory in order
    # and split into spatially separate slices between workers (no shared cache lines).
    first = indices.min(axis=1) if len(indices) else np.zeros(0, np.int64)
    order = np.lexsort((np.arange(len(indices)), first, colour))
    return order, np.asarray(offsets, np.int64)


def color_neighbours(start: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Partition particles into colours in which no two are neighbours, particle i's
    neighbours being other[start[i]:start[i + 1]] (a symmetric CSR: a matrix's rows), for
    passes that update particles in place (a point Gauss-Seidel). Greedy in index order: each
    particle takes the least colour none of its earlier neighbours has.

    Returns (order, offsets) as color_springs does: particles order[offsets[c]:offsets[c + 1]]
    form colour c, in increasing index."""
    count = len(start) - 1
    colour = np.full(count, -1, np.int64)
    for i in range(count):
        taken = colour[other[start[i]:start[i + 1]]]
        free = np.ones(len(taken) + 1, bool)
        free[taken[(taken >= 0) & (taken <= len(taken))]] = False
        colour[i] = int(np.argmax(free))
    order = np.argsort(colour, kind="stable")
    return order, np.concatenate([[0], np.cumsum(np.bincount(colour, minlength=1))])


class Cloth:
    """A mass-spring body ready to simulate: rest positions, lumped masses, springs, pins.

    Arrays (read-only numpy, entity-first names):
      particle_position  start positions [m], (N, 3): where the body is placed
      rest_position      rest positions [m], (N, 3): the shape it stores no energy in (where
                         every rest length, area, metric and angle below comes from); the
                         start positions unless given (rest=)
      particle_mass      masses [kg], (N,): area x density / 3 per triangle corner (Stuyck 4.2),
                         + material.hem_mass on each hem particle, then
                         `particle_mass_override`
      hem                (N,) bool: the particles that got hem mass
      ghost              (N,) bool: simulated, never drawn (hair's ghost particles)
      pinned             (N,) bool; pinned particles have inverse mass 0
      spring_indices     (S, 2) int, i < j
      spring_rest_length (S,) [m], from the reference configuration
      spring_stiffness   (S,) [N/m]
      spring_damping     (S,) [kg/s]
      spring_kind        (S,) SpringKind values
      triangle_edge_spring (T, 3): spring along edge (t0,t1), (t1,t2), (t2,t0), or -1
      triangle_face      (T,): the Fabric triangle (face) each mesh triangle is, or -1
      altitude_indices   (A, 4) int: Selle et al. 2008's altitude springs, a particle p and
                         the face (a, b, c) opposite it in a tetrahedron (altitude_springs)
      altitude_rest_length (A,) [m]: rest altitude of p over its face, > 0
      altitude_stiffness (A,) [N/m], altitude_damping (A,) [kg/s]
      particle_body      (N,) int: which of the bodies joined by `combine` each particle is
                         in (0 for one body)
      seam_indices       (P, 2) int, i < j: particle pairs a garment's seams pull together
                         (physics/sewing.py; body/panels.py makes them)

    A body made of a Fabric has no springs but elements (energies/): its triangles
      face_indices       (F, 3) int: the membrane and bending triangles (the mesh's)
      face_gradient      (F, 3, 2): barycentric gradients in each one's rest warp/weft frame
      face_area          (F,) rest areas [m^2]
      face_moduli        (F, 4): (C11, C12, C22, C33) [N/m] (Fabric.membrane)
      face_damping       (F,) Rayleigh damping time [s] (Fabric.damping)
      face_compression   (F,) the compressive stiffness's fraction of the tensile
                         (Fabric.compression)
      face_bending       (F, 3, 3): B of the bending energy 1/2 dt^T B dt [N m] (at zero
                         curvature, for a Fabric with a bending_curve)
      face_components    (F, 3, 3): b[f, d, i], each hinge tangent's share of the change of
                         curvature k_d (energies/bending.curvature_components)
      face_curve         (F,) int: each triangle's curve in bending_curves, or -1
      bending_curves     the Fabrics' BendingCurves (body/bending_curve.py), a tuple
      face_hinge         (F, 3): the hinge across each edge (edge i opposite corner i), or -1
    and its interior edges, the hinges
      hinge_indices      (H, 4) int [a, b, c, d]: edge a-b, c and d opposite it
      hinge_faces        (H, 2): 3 f + i of its two triangles
      hinge_rest_angle   (H,) dihedral angles of the rest mesh [rad], 0 across a seam
    A garment's seams (seams=) join its panels' bending: an edge sewn to another is a hinge
    across the seam (energies/bending.hinges with particle_weld), flat at rest as a tailor
    sews two panels edge to edge, so the seam bends as the cloth does (no fin).
    (all empty for a body of springs).

    pinned: particle indices, an (N,) bool mask, or names of mesh.named_vertices() ("top",
    "top_left", "boundary", ...: the names scene files take), alone or in a list with indices.
    springs: explicit springs (see module doc).
    hem: the particles on the hem (Stuyck 4.2: the edge "folded double and stitched" carries
    material.hem_mass each): a name of mesh.named_vertices() ("boundary", a grid's "bottom",
    "left", ...), particle indices or an (N,) bool mask; default a grid's bottom edge, else
    the boundary. Pinned particles never get hem mass.
    particle_mass_override: {index: kg} applied last. particle_mass: (N,) masses [kg] that
    replace the area-lumped ones and hem mass (bodies without triangles need it).
    altitude_tetrahedra: (T, 4) particle indices; each tetrahedron gets the four altitude
    springs of Selle et al. 2008 (a corner kept at its rest height over the opposite face,
    signed, so the tetrahedron resists flattening and cannot invert without work) with the
    constants `altitude` (a SpringParams). Default none.
    material: a Material (Stuyck's springs) or a Fabric (elements). warp: a Fabric's warp
    direction (default a grid's columns, else x), projected into each triangle, or "uv": along
    the mesh's texture coordinate u in each triangle (Mesh.uvs).
    seams: (P, 2) particle pairs sewn together (Garment.seam_pairs); default none.
    rest: the rest shape, if not where the mesh places the body: a Mesh or (N, 3) positions
    [m] of the same particles, or "uv": the flat pattern of the mesh's texture coordinates,
    taken as metres (a garment's: Garment.mesh), at z = 0. Masses, rest lengths, a Fabric's
    rest metric and its hinges' rest angles come from it, as Marvelous Designer's and
    Blender's cloth take a garment's rest state from its pattern, not from where it is
    placed round a body (a skirt wrapped onto a cone then stores the bending of the flat
    panels bent round it). Default: the mesh's vertices.
    """

    def __init__(self, mesh: Mesh, material: Material | Fabric, pinned=(), springs=None,
                 particle_mass_override: Mapping[int, float] | None = None,
                 particle_mass=None, hem=None, ghost=None, altitude_tetrahedra=None,
                 altitude: SpringParams | None = None, warp=None, seams=None, rest=None):
        require(isinstance(mesh, Mesh), "mesh", mesh, "a ti_cloth.Mesh")
        require(isinstance(material, (Material, Fabric)), "material", material,
                "a ti_cloth.Material or a ti_cloth.Fabric")
        fabric = isinstance(material, Fabric)
        require(not fabric or (springs is None and altitude_tetrahedra is None), "springs",
                springs, "None for a Fabric body (its forces come from its triangles)")
        require(not fabric or mesh.triangle_count > 0, "mesh.triangles", mesh.triangles.shape,
                "at least one triangle for a Fabric body")
        require(warp is None or fabric, "warp", warp,
                "None for a body of springs (a Material has no grain; a Fabric's warp sets it)")
        self.mesh = mesh
        self.material = material
        n = mesh.vertex_count
        self.particle_position = mesh.vertices
        self.rest_position = _rest_positions(rest, mesh)
        r = self.rest_position

        self.pinned = index_mask("pinned", named_particles("pinned", pinned, mesh), n)
        self.ghost = index_mask("ghost", () if ghost is None else ghost, n)
        self.hem = np.zeros(n, bool)
        if particle_mass is not None:
            mass = as_array("particle_mass", particle_mass, np.float64, (n,)).copy()
            require(bool(np.all(mass >= 0)), "particle_mass", mass.min(), "masses >= 0 kg")
        else:
            require(mesh.triangle_count > 0, "mesh.triangles", mesh.triangles.shape,
                    "at least one triangle (masses come from triangle areas; pass particle_mass= "
                    "for a mesh without triangles)")
            mass = lumped_masses(r, mesh.triangles, material.density)
            self.hem = _hem_mask(hem, mesh) & ~self.pinned
            mass[self.hem] += material.hem_mass
        for i, m in (particle_mass_override or {}).items():
            require(isinstance(i, (int, np.integer)) and 0 <= i < n, "particle_mass_override key",
                    i, f"a particle index in [0, {n - 1}]")
            mass[i] = finite_number(f"particle_mass_override[{i}]", m, 0.0, unit="kg")
        massless = np.flatnonzero((mass <= 0) & ~self.pinned)
        require(len(massless) == 0, f"particle_mass[{massless[:1].tolist()}]", 0.0,
                f"> 0 kg for every unpinned particle ({len(massless)} massless: "
                f"{massless[:5].tolist()}...); pin them, give them triangles or set their mass")
        self.particle_mass = mass

        if fabric:
            pairs, kind = np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
        elif springs is not None:
            pairs, kind = _explicit_springs(springs, n)
        elif mesh.grid_shape is not None:
            pairs, kind = unique_springs(grid_springs(*mesh.grid_shape))
        elif mesh.triangle_count:
            pairs, kind = unique_springs(mesh_springs(mesh.triangles))
        else:
            pairs, kind = np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
        if mesh.triangle_count and springs is None and mesh.grid_shape is None:
            _warn_if_nonmanifold(mesh, fabric)
        self.spring_indices = pairs
        self.spring_kind = kind
        self.spring_rest_length = np.linalg.norm(r[pairs[:, 0]] - r[pairs[:, 1]], axis=1)
        params = ([material.springs(k) for k in SpringKind] if not fabric
                  else [SpringParams(0.0)] * len(SpringKind))
        self.spring_stiffness = np.array([p.k for p in params])[kind]
        self.spring_damping = np.array([p.kd for p in params])[kind]
        self.triangle_edge_spring = _edge_springs(mesh.triangles, pairs, n)
        self.altitude_indices, self.altitude_rest_length = (
            altitude_springs(r, altitude_tetrahedra) if altitude_tetrahedra is not None
            else (np.zeros((0, 4), np.int64), np.zeros(0)))
        require(altitude is None or isinstance(altitude, SpringParams), "altitude", altitude,
                "None or a SpringParams(k, kd)")
        altitude = altitude or SpringParams(0.0)
        self.altitude_stiffness = np.full(self.altitude_count, altitude.k)
        self.altitude_damping = np.full(self.altitude_count, altitude.kd)
        self.particle_body = np.zeros(n, np.int64)
        self.seam_indices = _seam_pairs(seams, n)
        self._build_elements(material if fabric else None, warp)
        self._freeze()

    def _build_elements(self, fabric: Fabric | None, warp) -> None:
        """The face_* and hinge_* arrays (class doc): a Fabric's triangles and hinges, or none."""
        if fabric is not None:
            triangles = self.mesh.triangles
            moduli, flexural, damping = fabric.membrane, fabric.flexural, fabric.damping
            compression = fabric.compression
        else:
            triangles = np.zeros((0, 3), np.int64)
            moduli, flexural, damping, compression = (0.0,) * 4, (0.0,) * 3, 0.0, 1.0
        count = len(triangles)
        x = self.rest_position
        self.triangle_face = (np.arange(count) if fabric is not None
                              else np.full(len(self.mesh.triangles), -1))
        self.face_indices = triangles
        rest = Mesh(x, self.mesh.triangles, grid_shape=self.mesh.grid_shape, uvs=self.mesh.uvs)
        direction = warp_directions(rest, warp if fabric else None)
        _warn_if_warp_is_normal(direction, x, triangles, warp)
        self.face_gradient, self.face_area = material_frames(x, triangles, direction)
        self.face_moduli = np.tile(moduli, (count, 1))
        self.face_damping = np.full(count, damping)
        self.face_compression = np.full(count, compression)
        (self.hinge_indices, self.hinge_faces, self.face_hinge,
         face_sign) = hinges(triangles, self.particle_weld)
        self.face_components = curvature_components(self.face_gradient, face_sign)
        self.face_bending = bending_matrices(self.face_components, self.face_area,
                                             np.tile(flexural, (count, 1)))
        curve = fabric.bending_curve if fabric is not None else None
        self.bending_curves = () if curve is None else (curve,)
        self.face_curve = np.full(count, -1 if curve is None else 0)
        across = np.any(second_edge(self) != self.hinge_indices[:, :2], axis=1)
        self.hinge_rest_angle = np.where(across, 0.0, dihedral_angles(x, self.hinge_indices))

    ELEMENT_ARRAYS = ("face_indices", "face_gradient", "face_area", "face_moduli", "face_damping",
                      "face_compression", "face_bending", "face_components", "face_curve",
                      "face_hinge", "hinge_indices", "hinge_faces", "hinge_rest_angle")

    def _freeze(self) -> None:
        for name in ("rest_position", "particle_mass", "particle_body", "pinned", "hem", "ghost",
                     "spring_indices", "spring_kind", "spring_rest_length",
                     "spring_stiffness", "spring_damping", "triangle_edge_spring", "triangle_face", "altitude_indices",
                     "altitude_rest_length", "altitude_stiffness", "altitude_damping",
                     "seam_indices") + self.ELEMENT_ARRAYS:
            getattr(self, name).flags.writeable = False

    @classmethod
    def combine(cls, bodies) -> "Cloth":
        """One Cloth holding several bodies side by side (one simulation steps them all):
        particles, springs, triangles and tetrahedra renumbered in order; body b's particles
        are those with particle_body == b, in order. All must use the same damping model."""
        bodies = list(bodies)
        require(len(bodies) > 0 and all(isinstance(b, Cloth) for b in bodies), "bodies", bodies,
                "a non-empty list of Cloth objects")
        damping = {b.damping for b in bodies}
        require(len(damping) == 1, "bodies damping models", sorted(damping),
                "one damping model for every body")
        particle_offsets = np.cumsum([0] + [b.particle_count for b in bodies])
        spring_offsets = np.cumsum([0] + [b.spring_count for b in bodies])

        def joined(name, shift=None):
            parts = [getattr(b, name) for b in bodies]
            if shift is not None:
                parts = [np.where(p >= 0, p + o, p) for p, o in zip(parts, shift)]
            return np.concatenate(parts)

        def mesh_cells(name):
            return np.concatenate([getattr(b.mesh, name) + o for b, o in zip(bodies, particle_offsets)])

        body = cls.__new__(cls)
        body.mesh = Mesh(joined("particle_position"), mesh_cells("triangles"),
                         tetrahedra=mesh_cells("tetrahedra"))
        body.material = bodies[0].material
        body.particle_position = body.mesh.vertices
        body.rest_position = joined("rest_position")
        body.particle_mass = joined("particle_mass")
        body.pinned = joined("pinned")
        body.hem = joined("hem")
        body.ghost = joined("ghost")
        body.spring_indices = joined("spring_indices", particle_offsets)
        body.spring_kind = joined("spring_kind")
        body.spring_rest_length = joined("spring_rest_length")
        body.spring_stiffness = joined("spring_stiffness")
        body.spring_damping = joined("spring_damping")
        body.triangle_edge_spring = joined("triangle_edge_spring", spring_offsets)
        body.altitude_indices = joined("altitude_indices", particle_offsets)
        body.seam_indices = joined("seam_indices", particle_offsets)
        for name in ("altitude_rest_length", "altitude_stiffness", "altitude_damping",
                     "face_gradient", "face_area", "face_moduli", "face_damping",
                     "face_compression", "face_bending", "face_components", "hinge_rest_angle"):
            setattr(body, name, joined(name))
        body.bending_curves = tuple(c for b in bodies for c in b.bending_curves)
        body.face_curve = joined("face_curve", np.cumsum([0] + [len(b.bending_curves)
                                                                for b in bodies]))
        face_offsets = np.cumsum([0] + [b.face_count for b in bodies])
        hinge_offsets = np.cumsum([0] + [b.hinge_count for b in bodies])
        body.face_indices = joined("face_indices", particle_offsets)
        body.hinge_indices = joined("hinge_indices", particle_offsets)
        body.face_hinge = joined("face_hinge", hinge_offsets)
        body.triangle_face = joined("triangle_face", face_offsets)
        body.hinge_faces = joined("hinge_faces", 3 * face_offsets)
        first_body = np.cumsum([0] + [b.body_count for b in bodies])
        body.particle_body = np.concatenate([b.particle_body + k
                                             for b, k in zip(bodies, first_body)])
        body._freeze()
        return body

    def renumbered(self, order) -> "Cloth":
        """The same body with particle order[i] as particle i (a permutation of the particles):
        every per-particle array reordered, every index array relabelled (springs keep
        i < j), the mesh without its grid layout (its vertices are no longer row-major; the
        springs, built from it, stay)."""
        order = as_array("order", order, np.int64, (self.particle_count,))
        rank = np.full(self.particle_count, -1, np.int64)
        rank[order] = np.arange(self.particle_count)
        require(bool((rank >= 0).all()), "order", order.tolist()[:8],
                f"a permutation of the {self.particle_count} particles")
        body = copy.copy(self)
        mesh = self.mesh
        body.mesh = Mesh(mesh.vertices[order], rank[mesh.triangles],
                         tetrahedra=rank[mesh.tetrahedra],
                         uvs=None if mesh.uvs is None else mesh.uvs[order])
        body.particle_position = body.mesh.vertices
        for name in ("rest_position", "particle_mass", "particle_body", "pinned", "hem", "ghost"):
            setattr(body, name, getattr(self, name)[order])
        body.spring_indices = np.sort(rank[self.spring_indices], axis=1)
        body.seam_indices = np.sort(rank[self.seam_indices], axis=1)
        for name in ("altitude_indices", "face_indices", "hinge_indices"):
            setattr(body, name, rank[getattr(self, name)])
        body._freeze()
        return body

    @classmethod
    def from_particles(cls, positions, particle_mass, springs, material: Material | None = None,
                       pinned=(), ghost=None, altitude_tetrahedra=None,
                       altitude: SpringParams | None = None) -> "Cloth":
        """A body without a surface: particles [m], masses [kg], explicit springs (S, 2) or
        {kind: (S, 2)}; spring constants come from `material` by kind; ghost: particles that
        are simulated but never drawn (indices or a mask); altitude springs as in Cloth."""
        return cls(Mesh(positions, np.zeros((0, 3), np.int64)), material or Material(),
                   pinned=pinned, springs=springs, particle_mass=particle_mass, ghost=ghost,
                   altitude_tetrahedra=altitude_tetrahedra, altitude=altitude)

    @property
    def particle_count(self) -> int:
        return len(self.particle_position)

    @property
    def body_count(self) -> int:
        return int(self.particle_body.max()) + 1

    @property
    def spring_count(self) -> int:
        return len(self.spring_indices)

    @property
    def altitude_count(self) -> int:
        return len(self.altitude_indices)

    @property
    def face_count(self) -> int:
        return len(self.face_indices)

    @property
    def hinge_count(self) -> int:
        return len(self.hinge_indices)

    @property
    def fabric(self) -> bool:
        """Whether the body has elements (a Fabric's) rather than springs only."""
        return self.face_count > 0

    @property
    def softened(self) -> bool:
        """Whether some triangle resists compression less than tension (Fabric.compression)."""
        return bool((self.face_compression < 1.0).any())

    @property
    def curved(self) -> bool:
        """Whether some hinge bends by a BendingCurve (its rigidity depends on curvature)."""
        return bool(self.hinge_count and (self.face_curve >= 0).any())

    @property
    def damping(self) -> str:
        """The springs' damping model ("axial" for a Fabric's body, which has none)."""
        return self.material.damping if isinstance(self.material, Material) else "axial"

    @property
    def particle_weld(self) -> np.ndarray:
        """(N,) each particle's representative among those its seams sew together (the least
        index; itself off the seams): a hinge crosses a seam where its edges' ends match."""
        return welded(self.seam_indices, self.particle_count)

    @property
    def mean_edge(self) -> float:
        """The mean rest length [m] of the body's edges: its triangles' (each edge once),
        else its stretch springs' (strings, hair); 0 for particles alone."""
        triangles = self.mesh.triangles
        if len(triangles):
            pairs = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
            pairs = np.unique(pairs, axis=0)
        else:
            pairs = self.spring_indices[self.spring_kind == SpringKind.STRETCH]
        if len(pairs) == 0:
            return 0.0
        r = self.rest_position
        return float(np.linalg.norm(r[pairs[:, 0]] - r[pairs[:, 1]], axis=1).mean())

    def spring_count_by_kind(self) -> dict[str, int]:
        return {k.name.lower(): int(np.sum(self.spring_kind == k)) for k in SpringKind}

    def __repr__(self) -> str:
        return (f"Cloth(particles={self.particle_count}, springs={self.spring_count_by_kind()}, "
                f"pinned={int(self.pinned.sum())}, mass={self.particle_mass.sum():.4g} kg)")


def _rest_positions(rest, mesh: Mesh) -> np.ndarray:
    """The (N, 3) rest positions of Cloth(rest=...) (class doc)."""
    if rest is None:
        return mesh.vertices
    if isinstance(rest, str):
        require(rest == "uv", "rest", rest, 'None, "uv", a Mesh or (N, 3) positions')
        require(mesh.uvs is not None, "rest", rest,
                "a mesh with texture coordinates in metres (a garment's pattern) for \"uv\"")
        flat = np.zeros((mesh.vertex_count, 3))
        flat[:, :2] = mesh.uvs
        return flat
    if isinstance(rest, Mesh):
        require(rest.vertex_count == mesh.vertex_count
                and np.array_equal(rest.triangles, mesh.triangles), "rest", rest,
                f"a Mesh of the same {mesh.vertex_count} vertices and triangles as the body's")
        rest = rest.vertices
    positions = as_array("rest", rest, np.float64, (mesh.vertex_count, 3))
    require(bool(np.isfinite(positions).all()), "rest", "non-finite positions",
            "finite positions [m]")
    return positions


def index_mask(field: str, value, n: int) -> np.ndarray:
    """(n,) bool mask from particle indices or an (n,) bool mask; ValueError naming `field`."""
    value = np.asarray(value)
    require(value.size == 0 or value.dtype == bool or np.issubdtype(value.dtype, np.integer),
            field, value if value.size < 8 else f"array of {value.dtype}",
            "particle indices (ints) or an (N,) bool mask")
    if value.dtype == bool:
        require(value.shape == (n,), f"{field}.shape", value.shape, f"({n},) for a boolean mask")
        return value.copy()
    index = as_array(field, value, np.int64, (None,))
    bad = index[(index < 0) | (index >= n)]
    require(len(bad) == 0, field, bad[:3].tolist(), f"particle indices in [0, {n - 1}]")
    mask = np.zeros(n, bool)
    mask[index] = True
    return mask


def _warn_if_nonmanifold(mesh: Mesh, fabric: bool) -> None:
    """Say where the mesh is not a surface, and what the body does there (issue 40)."""
    edges, vertices = nonmanifold(mesh.triangles, mesh.vertex_count)
    found = []
    if len(edges):
        found.append(f"{len(edges)} edges shared by three or more triangles (first "
                     f"{edges[:5].tolist()}): each triangle keeps its "
                     f"{'membrane' if fabric else 'stretch and shear springs'}, but no "
                     f"{'hinge' if fabric else 'bend spring'} crosses them (those join exactly "
                     "two triangles), so the sheets turn freely about them")
    if len(vertices):
        found.append(f"{len(vertices)} vertices where separate sheets meet at a point (first "
                     f"{vertices[:5].tolist()}): the sheets are held together there only")
    if found:
        warnings.warn("Cloth: the mesh is not a manifold surface: " + "; ".join(found),
                      stacklevel=3)


def named_particles(field: str, value, mesh: Mesh):
    """`value` with the names scene files take ("top", "top_left", "boundary", ...:
    Mesh.named_vertices) replaced by their particles: a name, or a list of names and indices;
    anything else as it is. ValueError naming the field and the names allowed."""
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, (list, tuple)) or not any(isinstance(v, str) for v in items):
        return value
    names = mesh.named_vertices()
    chosen = []
    for item in items:
        if isinstance(item, str):
            require(item in names, field, item, f"particle indices or names of {list(names)}")
            chosen += names[item].tolist()
        else:
            chosen.append(item)
    return chosen


def _hem_mask(hem, mesh: Mesh) -> np.ndarray:
    """The hem particles of Cloth(hem=...) as a mask (see Cloth)."""
    if hem is None:
        hem = "bottom" if mesh.grid_shape is not None else "boundary"
    return index_mask("hem", named_particles("hem", hem, mesh), mesh.vertex_count)


def _explicit_springs(springs, n: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(springs, Mapping):
        springs = {SpringKind.STRETCH: springs}
    by_kind = {}
    for key, value in springs.items():
        try:
            kind = SpringKind[key.upper()] if isinstance(key, str) else SpringKind(key)
        except (KeyError, ValueError):
            raise ValueError(f"springs key must be one of {[k.name.lower() for k in SpringKind]}, "
                             f"got {key!r}") from None
        pairs = as_array(f"springs[{kind.name.lower()}]", value, np.int64, (None, 2))
        bad = np.flatnonzero((pairs < 0).any(1) | (pairs >= n).any(1) | (pairs[:, 0] == pairs[:, 1]))
        require(len(bad) == 0, f"springs[{kind.name.lower()}][{bad[:1].tolist()}]",
                pairs[bad[:1]].tolist(), f"two different particle indices in [0, {n - 1}]")
        by_kind[kind] = pairs
    total = sum(len(p) for p in by_kind.values())
    pairs, kind = unique_springs(by_kind)
    require(len(pairs) == total, "springs", f"{total - len(pairs)} repeated particle pair(s)",
            "each particle pair connected at most once")
    return pairs, kind


def _seam_pairs(seams, n: int) -> np.ndarray:
    """Seam pairs (P, 2) as sorted, distinct pairs of distinct particles."""
    if seams is None:
        return np.zeros((0, 2), np.int64)
    pairs = as_array("seams", seams, np.int64, (None, 2))
    bad = np.flatnonzero((pairs < 0).any(axis=1) | (pairs >= n).any(axis=1)
                        | (pairs[:, 0] == pairs[:, 1]))
    require(len(bad) == 0, f"seams[{bad[:1].tolist()}]", pairs[bad[:1]].tolist(),
            f"two different particle indices in [0, {n - 1}]")
    return np.unique(np.sort(pairs, axis=1), axis=0)


def _edge_springs(triangles: np.ndarray, pairs: np.ndarray, n: int) -> np.ndarray:
    """For each triangle edge, the index of the spring joining its ends, or -1."""
    if len(triangles) == 0 or len(pairs) == 0:
        return np.full((len(triangles), 3), -1, np.int64)
    edges = triangle_edges(triangles)
    keys = pairs[:, 0] * n + pairs[:, 1]
    order = np.argsort(keys)
    wanted = edges[:, 0] * n + edges[:, 1]
    pos = np.minimum(np.searchsorted(keys[order], wanted), len(keys) - 1)
    return np.where(keys[order][pos] == wanted, order[pos], -1).reshape(-1, 3)


def _warn_if_warp_is_normal(direction, x: np.ndarray, triangles: np.ndarray, warp) -> None:
    """Warn when a given warp direction is (nearly) normal to most triangles, whose grain
    then falls back to their first edge (membrane.material_frames): on a flat sheet, a warp
    along the sheet's normal is a mistake, not a grain."""
    if warp is None or isinstance(warp, str) or not len(triangles):
        return
    p = x[triangles]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    along = np.abs(normal @ direction) / np.linalg.norm(direction)
    count = int(np.sum(along > 1.0 - 1e-9))
    if count > len(triangles) // 2:
        warnings.warn(f"warp {list(map(float, direction))} is along the normal of {count} of "
                      f"{len(triangles)} triangles: their grain falls back to their first edge; "
                      "give a direction in the cloth's plane", stacklevel=4)


def warp_directions(mesh: Mesh, warp) -> np.ndarray:
    """The warp direction of Cloth(warp=...): a given (3,) direction, or "uv": in each triangle
    the direction in which its texture coordinate u grows at constant v (d x / d u, from the
    mesh's uvs; (T, 3)); by default a grid's first axis (its columns), or x."""
    if isinstance(warp, str):
        require(warp == "uv", "warp", warp, '"uv" or a direction [x, y, z]')
        require(mesh.uvs is not None, "warp", warp,
                "a direction, or a mesh with texture coordinates (Mesh.uvs, one per vertex)")
        return uv_warp(mesh)
    if warp is not None:
        direction = as_array("warp", warp, np.float64, (3,))
        length = float(np.linalg.norm(direction))
        require(0 < length < np.inf, "warp", direction.tolist(),
                "a non-zero direction of finite length")
        return direction
    if mesh.grid_shape is not None:
        return mesh.vertices[1] - mesh.vertices[0]
    return np.array([1.0, 0.0, 0.0])
