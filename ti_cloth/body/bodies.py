"""Builders for the mass-spring bodies other than a cloth sheet: the lecture's elastic string,
hair strands (Stuyck 4.6.1) and tetrahedral soft bodies (Stuyck 4.6.2). Each returns a Cloth
(the simulator's one body type) and runs on every integrator.
"""

from __future__ import annotations

import numpy as np

from ..inputs import limits
from ..inputs.validation import as_array, count, in_range, require
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
    along = length * (np.arange(n) / (n - 1))        # the same bits at every refinement
    positions = start + along[:, None] * _unit("direction", direction)
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


GHOST_SHARE = 0.2      # of a strand's mass carried by its ghost particles
GHOST_OFFSET = 0.5     # a ghost's distance from its segment's midpoint, in segment lengths


def hair(strands, segments: int, length: float, *, anchor=(0.0, 0.0, 0.0), radius: float = 0.1,
         directions=None, mass: float = 1e-3, stretch=SpringParams(50.0, 0.02),
         bend=SpringParams(5.0, 0.005), twist: SpringParams | None = None, ghosts: bool = True,
         curl=None, altitude: SpringParams | bool = True) -> Cloth:
    """Hair strands rooted on a head (Stuyck 4.6.1, fig. 4.5): chains of `segments` springs.

    strands: a count (roots spread evenly over the upper half of a sphere of `radius` [m]
        around `anchor` [m], strands growing outwards) or root positions [m], shape (S, 3),
        with `directions` (S, 3) (default: away from `anchor`).
    length: rest length of each strand [m] (along the curve); mass: mass of one strand [kg].
    stretch: springs between neighbouring strand particles.
    ghosts: True (Selle et al. 2008, the ghost particles of fig. 4.5): a ghost particle beside
        each segment, GHOST_OFFSET segment lengths off its midpoint and turned a quarter turn
        about the strand from the last, so the sequence root, ghost, particle, ghost, ... is a
        chain of tetrahedra; springs join each of its members to the next three: to the next
        (stretch constants), two on (strand particles: `stretch`, the strand's edges; ghosts:
        `bend`) and three on (`twist`, default `bend`: torsion). The root, its ghost and the
        next strand particle are pinned, so the root holds its direction. Ghosts carry
        GHOST_SHARE of the strand's mass and are never drawn.
        False: the plain chain, stretch (i, i+1) and bend (i, i+2) springs, the root pinned;
        nothing holds the root's direction, so strands hang.
    curl: None (straight) or (radius, pitch) [m]: a helical rest shape about the strand's
        direction (Iben et al. 2013), which the springs keep (with ghosts).

    Strand s holds particles s * (segments + 1) ... (s + 1) * (segments + 1) - 1 (root first);
    with ghosts, the ghost of its segment k is S * (segments + 1) + s * segments + k and
    `body.ghost` marks them. Move the head with Handle(np.flatnonzero(body.pinned), path).
    """
    segments = count("segments", segments, limits.SEGMENTS)
    length = in_range("length", length, limits.LENGTH)
    mass = in_range("mass", mass, limits.MASS)
    require(isinstance(ghosts, bool), "ghosts", ghosts, "True or False")
    require(isinstance(altitude, (bool, SpringParams)), "altitude", altitude,
            "True (the twist constants), False (none) or a SpringParams(k, kd)")
    anchor = as_array("anchor", anchor, np.float64, (3,))
    if isinstance(strands, (int, np.integer)) and not isinstance(strands, bool):
        strand_count = count("strands", strands, limits.STRANDS)
        per_strand = (2 * segments + 1) if ghosts else segments + 1
        limits.check_memory("strands", strands, strand_count * per_strand,
                            (3 + 4 * limits.ALTITUDE_SPRINGS * (altitude is not False)
                             if ghosts else 2)
                            * strand_count * per_strand)
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
    curve = _strand_curves(roots, normals, segments, length, curl)          # (S, n + 1, 3)
    material = Material(stretch=stretch, bend=bend or SpringParams(0.0),
                        shear=twist or bend or SpringParams(0.0))
    if altitude is True:
        altitude = material.shear
    strand_count, particles = len(roots), segments + 1
    if not ghosts:
        return Cloth.from_particles(curve.reshape(-1, 3),
                                    _chain_masses(strand_count, particles, mass),
                                    _chain_springs(strand_count, particles, bend is not None),
                                    material, np.arange(strand_count) * particles)
    ghost_position = _ghost_positions(curve)                                  # (S, n, 3)
    real = np.arange(strand_count * particles).reshape(strand_count, particles)
    ghost = strand_count * particles + np.arange(strand_count * segments).reshape(strand_count,
                                                                                  segments)
    sequence = np.empty((strand_count, 2 * segments + 1), np.int64)       # r0 g0 r1 g1 ... rn
    sequence[:, 0::2], sequence[:, 1::2] = real, ghost
    pairs = {step: np.stack([sequence[:, :-step], sequence[:, step:]], axis=-1) for step in (1, 2, 3)}
    strand_edge = np.zeros(pairs[2].shape[:2], bool)
    strand_edge[:, 0::2] = True                                  # (r_k, r_k+1), not (g_k, g_k+1)
    springs = {SpringKind.STRETCH: np.concatenate([pairs[1].reshape(-1, 2), pairs[2][strand_edge]]),
               SpringKind.BEND: pairs[2][~strand_edge], SpringKind.SHEAR: pairs[3].reshape(-1, 2)}
    strand_masses = _chain_masses(strand_count, particles, (1 - GHOST_SHARE) * mass)
    ghost_masses = np.full(strand_count * segments, GHOST_SHARE * mass / segments)
    pinned = np.concatenate([real[:, :2].ravel(), ghost[:, 0]])
    tetrahedra = np.stack([sequence[:, a:a + 4] for a in range(2 * segments - 2)], axis=1)
    return Cloth.from_particles(np.concatenate([curve.reshape(-1, 3), ghost_position.reshape(-1, 3)]),
                                np.concatenate([strand_masses, ghost_masses]), springs, material,
                                pinned, ghost=np.arange(len(strand_masses) + len(ghost_masses))
                                >= len(strand_masses),
                                altitude_tetrahedra=tetrahedra.reshape(-1, 4) if altitude else None,
                                altitude=altitude or None)


def _strand_curves(roots, normals, segments: int, length: float, curl) -> np.ndarray:
    """Rest positions of every strand's particles, (S, segments + 1, 3): straight along its
    direction, or a helix of curl = (radius, pitch) about it, the root on the helix, particles
    spaced evenly along the helix's arc."""
    arc = length * (np.arange(segments + 1) / segments)     # the same bits when refined
    if curl is None:
        return roots[:, None, :] + arc[None, :, None] * normals[:, None, :]
    curl = as_array("curl", curl, np.float64, (2,))
    helix_radius = in_range("curl[0] (radius)", curl[0], limits.LENGTH)
    pitch = in_range("curl[1] (pitch)", curl[1], limits.LENGTH)
    turn = np.hypot(2 * np.pi * helix_radius, pitch)                     # arc length per turn
    u = _perpendicular(normals)
    v = np.cross(normals, u)
    angle = 2 * np.pi * arc / turn
    return (roots[:, None, :]
            + helix_radius * (np.cos(angle)[None, :, None] - 1) * u[:, None, :]
            + helix_radius * np.sin(angle)[None, :, None] * v[:, None, :]
            + (pitch * arc / turn)[None, :, None] * normals[:, None, :])


def _perpendicular(directions: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit row of `directions`."""
    helper = np.where(np.abs(directions[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(directions, helper)
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _ghost_positions(curve: np.ndarray) -> np.ndarray:
    """A ghost beside each segment of each strand, (S, n, 3): GHOST_OFFSET segment lengths from
    the midpoint, perpendicular to the segment, a quarter turn further round the strand than
    the last (a frame carried along the strand by parallel transport), so that each root,
    ghost, particle, ghost quadruple spans a tetrahedron of volume > 0."""
    segment = np.diff(curve, axis=1)
    length = np.linalg.norm(segment, axis=2, keepdims=True)
    tangent = segment / length
    ghosts = np.empty_like(segment)
    u = _perpendicular(tangent[:, 0])
    for k in range(segment.shape[1]):
        t = tangent[:, k]
        u = u - np.sum(u * t, axis=1, keepdims=True) * t
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        offset = np.cos(k * np.pi / 2) * u + np.sin(k * np.pi / 2) * np.cross(t, u)
        ghosts[:, k] = curve[:, k] + 0.5 * segment[:, k] + GHOST_OFFSET * length[:, k] * offset
    return ghosts


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
