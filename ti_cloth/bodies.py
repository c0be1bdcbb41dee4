"""Builders for the mass-spring bodies other than a cloth sheet: the lecture's elastic string,
hair strands (Stuyck 4.6.1) and tetrahedral soft bodies (Stuyck 4.6.2). Each returns a Cloth
(the simulator's one body type) and runs on every integrator.
"""

from __future__ import annotations

import numpy as np

from . import limits
from ._validate import as_array, count, in_range, require
from .material import Material, SpringKind, SpringParams
from .mesh import Mesh, tet_grid_mesh
from .topology import Cloth, unique_springs

STRING_ENDS = ("start", "both", "none")
END_MASSES = ("half", "full")


def _unit(name: str, value) -> np.ndarray:
    v = as_array(name, value, np.float64, (3,))
    length = float(np.linalg.norm(v))
    require(length > 0, name, v.tolist(), "a non-zero vector")
    return v / length


def _chain_masses(strands: int, particles: int, mass: float, end_mass: str = "half") -> np.ndarray:
    """A strand's `mass` over its particles: "half", each segment's mass split half to either
    end (lumped: the ends carry half as much); "full", the same mass m = mass / particles on
    every particle (the lecture's string)."""
    if end_mass == "full":
        return np.full(strands * particles, mass / particles)
    per_particle = np.full(particles, mass / (particles - 1))
    per_particle[[0, -1]] *= 0.5
    return np.tile(per_particle, strands)


def string(n: int, length: float, *, mass: float = 0.1, stretch=SpringParams(500.0, 0.1),
           bend: SpringParams | None = None, start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0),
           fixed: str = "start", end_mass: str = "half") -> Cloth:
    """The lecture's elastic string: n particles in a straight line, neighbours joined by springs.

    length: rest length [m] from the first particle to the last. mass: total mass [kg], each
    segment's share split between its two ends. stretch: constants of the springs between
    neighbours (k [N/m] per spring, kd [kg/s]). bend: constants of springs joining particles two
    apart (None: no bend springs, a perfectly flexible string). start: position of particle 0 [m];
    direction: the line's direction. fixed: "start" (particle 0 fixed, the lecture's wall; the
    other end free: it simply has one spring, which is what the lecture's p_end = p_end-1 boundary
    approximates), "both" (the string held at both ends) or "none". end_mass: "half" (the ends
    carry half a segment's mass, as lumping segments gives) or "full" (every particle the same
    mass, mass / n: the lecture's m a_i = m g + ... for every i).
    """
    n = count("n", n, limits.CHAIN)
    limits.check_memory("n", n, n, 2 * n)
    length = in_range("length", length, limits.LENGTH)
    mass = in_range("mass", mass, limits.MASS)
    require(fixed in STRING_ENDS, "fixed", fixed, f"one of {STRING_ENDS}")
    require(end_mass in END_MASSES, "end_mass", end_mass, f"one of {END_MASSES}")
    start = as_array("start", start, np.float64, (3,))
    positions = start + np.linspace(0.0, length, n)[:, None] * _unit("direction", direction)
    springs = _chain_springs(1, n, bend is not None)
    pinned = {"start": [0], "both": [0, n - 1], "none": []}[fixed]
    material = Material(stretch=stretch, bend=bend or SpringParams(0.0))
    return Cloth.from_particles(positions, _chain_masses(1, n, mass, end_mass), springs, material,
                                pinned)


def _chain_springs(strands: int, particles: int, bend: bool) -> dict[SpringKind, np.ndarray]:
    """Stretch springs (i, i+1) and, with `bend`, (i, i+2) along every strand."""
    first = (np.arange(strands) * particles)[:, None]
    springs = {SpringKind.STRETCH: (first + np.arange(particles - 1)).reshape(-1, 1) + [0, 1]}
    if bend and particles > 2:
        springs[SpringKind.BEND] = (first + np.arange(particles - 2)).reshape(-1, 1) + [0, 2]
    return springs


def hair(strands, segments: int, length: float, *, anchor=(0.0, 0.0, 0.0), radius: float = 0.1,
         directions=None, mass: float = 1e-3, stretch=SpringParams(50.0, 0.02),
         bend=SpringParams(5.0, 0.005)) -> Cloth:
    """Hair strands rooted on a head (Stuyck 4.6.1): chains of `segments` springs each.

    strands: a count (roots spread evenly over the upper half of a sphere of `radius` [m]
        around `anchor` [m], strands growing outwards) or root positions [m], shape (S, 3),
        with `directions` (S, 3) (default: away from `anchor`).
    length: rest length of each strand [m]; mass: mass of one strand [kg].
    stretch: springs between neighbours; bend: springs between particles two apart (None: none).

    Strand s holds particles s * (segments + 1) ... (s + 1) * (segments + 1) - 1; its root (the
    first) is pinned; move the head with Handle(np.flatnonzero(body.pinned), path).
    No ghost particles (Stuyck fig. 4.5): a straight chain of points has no orientation to
    twist, so torsion has nothing to act on; ghosts matter for curly rest shapes, which these
    strands do not have. Stretch and bend springs alone give the strand's swing and stiffness.
    """
    segments = count("segments", segments, limits.SEGMENTS)
    length = in_range("length", length, limits.LENGTH)
    mass = in_range("mass", mass, limits.MASS)
    anchor = as_array("anchor", anchor, np.float64, (3,))
    if isinstance(strands, (int, np.integer)) and not isinstance(strands, bool):
        strand_count = count("strands", strands, limits.STRANDS)
        limits.check_memory("strands", strands, strand_count * (segments + 1),
                            2 * strand_count * segments)
        radius = in_range("radius", radius, limits.LENGTH)
        normals = _upper_hemisphere(strand_count)
        roots = anchor + radius * normals
    else:
        roots = as_array("strands", strands, np.float64, (None, 3))
        require(len(roots) > 0, "strands", roots.shape, "an int >= 1 or root positions (S, 3)")
        normals = roots - anchor
    if directions is not None:
        normals = as_array("directions", directions, np.float64, (len(roots), 3))
    lengths = np.linalg.norm(normals, axis=1)
    bad = np.flatnonzero(lengths == 0)
    require(len(bad) == 0, f"directions[{bad[:1].tolist()}]", 0.0,
            "non-zero (a root may not sit on the anchor without an explicit direction)")
    normals = normals / lengths[:, None]
    steps = np.linspace(0.0, length, segments + 1)
    positions = (roots[:, None, :] + steps[None, :, None] * normals[:, None, :]).reshape(-1, 3)
    particles = segments + 1
    springs = _chain_springs(len(roots), particles, bend is not None)
    pinned = np.arange(len(roots)) * particles
    material = Material(stretch=stretch, bend=bend or SpringParams(0.0))
    return Cloth.from_particles(positions, _chain_masses(len(roots), particles, mass), springs,
                                material, pinned)


def _upper_hemisphere(count: int) -> np.ndarray:
    """`count` unit vectors spread evenly (a Fibonacci spiral) over the half sphere y >= 0."""
    k = np.arange(count) + 0.5
    y = 1.0 - k / count
    ring = np.sqrt(1.0 - y * y)
    angle = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([ring * np.cos(angle), y, ring * np.sin(angle)], axis=1)


def soft_body(mesh: Mesh, density: float = 1000.0, stretch=SpringParams(2e4, 5.0),
              pinned=()) -> Cloth:
    """A tetrahedral soft body (Stuyck 4.6.2): springs along every tetrahedron edge.

    mesh: a Mesh with tetrahedra (tet_grid_mesh, or load_mesh of a volume mesh).
    density: [kg/m^3]; each tetrahedron's rest volume x density goes a quarter to each corner.
    stretch: constants of the edge springs (k [N/m], kd [kg/s]).
    Raises ValueError for a tetrahedron of zero volume, which would carry no mass.
    """
    require(isinstance(mesh, Mesh) and len(mesh.tetrahedra) > 0, "mesh", mesh,
            "a Mesh with tetrahedra (tet_grid_mesh or a volume mesh file)")
    density = in_range("density", density, limits.DENSITY)
    volume = np.abs(mesh.tetrahedron_volumes())
    longest = np.max(np.linalg.norm(mesh.vertices[mesh.tetrahedra][:, :, None]
                                    - mesh.vertices[mesh.tetrahedra][:, None], axis=3), axis=(1, 2))
    flat = np.flatnonzero(volume <= 1e-12 * longest ** 3)
    if len(flat):
        t = int(flat[0])
        raise ValueError(f"tetrahedra[{t}] (vertices {mesh.tetrahedra[t].tolist()}) must have a "
                         f"volume > 0 m^3, got {volume[t]:.3g} m^3 ({len(flat)} flat tetrahedra)")
    mass = np.bincount(mesh.tetrahedra.ravel(), weights=np.repeat(volume * density / 4.0, 4),
                       minlength=mesh.vertex_count)
    edges = mesh.tetrahedra[:, [0, 0, 0, 1, 1, 2]], mesh.tetrahedra[:, [1, 2, 3, 2, 3, 3]]
    pairs, _ = unique_springs({SpringKind.STRETCH: np.stack([e.ravel() for e in edges], axis=1)})
    return Cloth(mesh, Material(stretch=stretch), pinned=pinned, springs=pairs, particle_mass=mass)


def tet_block(cells=(4, 4, 4), size=(0.4, 0.4, 0.4), origin=(0.0, 0.0, 0.0),
              density: float = 1000.0, stretch=SpringParams(2e4, 5.0), pinned=()) -> Cloth:
    """A box of cells[0] x cells[1] x cells[2] cubes of `size` [m] at `origin`, six tetrahedra
    per cube (tet_grid_mesh), as a soft_body of `density` [kg/m^3]."""
    return soft_body(tet_grid_mesh(cells, size, origin), density, stretch, pinned)
