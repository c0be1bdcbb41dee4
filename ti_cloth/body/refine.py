"""Refining a body: the same body at `factor` times its resolution (the study's and the
advisor's resolution axis, scene.build(resolution=f)).

    mesh, refinement = subdivide(mesh, 2)       # a triangle mesh: midpoint subdivision
    grid_refinement(rows, cols, 4)              # a grid: (n - 1) f + 1 per side
    chain_refinement(strands, segments, 2, ghosts=True)   # strings and hair: f x segments
    tet_refinement(cells, 2)                    # a tet block: f x cells per axis

A builder makes the refined body in its own numbering; a Refinement says which of its
particles are the coarse body's (`coarse`: builder index of coarse particle i) and on which
coarse edge every other one lies (`carrier`), so selections carry over: a coarse particle is
selected as it was, a new one when both ends of its coarse edge are (a pinned edge stays
pinned along its length). The body is then renumbered, coarse particles first
(Cloth.renumbered), so particle i of a scene is particle i of every refinement.

Constants that stand for a material keep it (springs_at): a spring network of constant k
and spacing h stands for a modulus k h^(2 - d) in d dimensions (a string's EA = k h, a sheet's
2-D modulus = k for the same pattern, a block's E = k / h), so a refined string's springs
are f x stiffer, a sheet's the same, a block's f x softer; damping constants scale alike. A
hem's mass is per particle, f x more of them along the hem: each carries 1/f of it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..inputs.validation import require
from .material import SpringParams
from .mesh import Mesh, split_triangles

NONE = -1


@dataclass(frozen=True)
class Refinement:
    """coarse: (n,) the builder's index of each coarse particle; carrier: (N, 2) per particle
    of the refined body (builder numbering) the coarse particles at the ends of the coarse
    edge it lies on, (a, a) for coarse particle a itself, (NONE, NONE) inside a coarse face or
    cell."""

    coarse: np.ndarray
    carrier: np.ndarray

    @property
    def order(self) -> np.ndarray:
        """The builder's indices in the refined body's order: the coarse particles as they
        were, then the others in the builder's order."""
        new = np.ones(len(self.carrier), bool)
        new[self.coarse] = False
        return np.concatenate([self.coarse, np.flatnonzero(new)])

    def carry(self, selected) -> np.ndarray:
        """The refined body's particles (builder numbering, sorted) that a selection of coarse
        particles becomes: those particles, and every new one whose coarse edge has both ends
        selected."""
        mask = np.zeros(len(self.coarse), bool)
        mask[np.asarray(selected, np.int64)] = True
        a, b = self.carrier.T
        on_edge = (a != NONE) & (b != NONE)
        chosen = np.zeros(len(self.carrier), bool)
        chosen[on_edge] = mask[a[on_edge]] & mask[b[on_edge]]
        return np.flatnonzero(chosen)


def _lattice(shape, factor: int) -> Refinement:
    """A regular lattice of coarse `shape` (points per axis, C order) refined `factor` times
    per cell: refined point p lies on the coarse edge from its cell's corner q = p // f to
    q + s (s = 0/1 per axis: the axes where p is off q) when p is off q by the same amount on
    each of those axes (the grids' and tet blocks' cells are cut so that every such 0/1 step
    is an edge: grid_mesh's diagonals, Kuhn's tetrahedra)."""
    shape = np.asarray(shape)
    fine = (shape - 1) * factor + 1
    point = np.stack(np.unravel_index(np.arange(int(np.prod(fine))), fine), axis=1)
    corner, offset = np.divmod(point, factor)
    steps = np.where(offset > 0, 1, 0)
    t = offset.max(axis=1)
    along = np.all((offset == 0) | (offset == t[:, None]), axis=1)
    a = np.ravel_multi_index(corner.T, shape)
    b = np.ravel_multi_index(np.minimum(corner + steps, shape - 1).T, shape)
    carrier = np.where(along[:, None], np.stack([a, b], axis=1), NONE)
    coarse = np.ravel_multi_index((np.stack(np.unravel_index(np.arange(int(np.prod(shape))), shape),
                                            axis=1) * factor).T, fine)
    return Refinement(coarse, carrier)


def grid_refinement(rows: int, cols: int, factor: int) -> Refinement:
    """A row-major rows x cols grid refined to ((rows - 1) f + 1) x ((cols - 1) f + 1)."""
    return _lattice((rows, cols), factor)


def tet_refinement(cells, factor: int) -> Refinement:
    """tet_grid_mesh(cells) refined to f x cells per axis."""
    return _lattice(np.asarray(cells) + 1, factor)


def chain_refinement(strands: int, segments: int, factor: int, ghosts: bool) -> Refinement:
    """`strands` chains of `segments` segments (a string: one; hair: bodies.hair's numbering,
    strand particles first, then with `ghosts` one ghost per segment) refined to f x segments.
    Coarse ghost k of a strand becomes the ghost of refined segment k f, the first of the
    segments that split coarse segment k (it is rebuilt beside that shorter segment, so
    it is the same ghost in role, not in place)."""
    fine = segments * factor
    strand = np.arange(strands)[:, None]
    real = strand * (fine + 1) + np.arange(segments + 1) * factor
    coarse_real = strand * (segments + 1) + np.arange(segments + 1)
    count = strands * (fine + 1) + (strands * fine if ghosts else 0)
    carrier = np.full((count, 2), NONE)
    k = np.arange(fine + 1)
    lo = strand * (segments + 1) + np.minimum(k // factor, segments)
    hi = strand * (segments + 1) + np.minimum(-(-k // factor), segments)
    carrier[(strand * (fine + 1) + k).ravel()] = np.stack([lo.ravel(), hi.ravel()], axis=1)
    coarse = [real.ravel()]
    if ghosts:
        first = strands * (fine + 1)
        ghost = first + strand * fine + np.arange(segments) * factor
        carrier[ghost.ravel()] = (strands * (segments + 1) + np.arange(strands * segments))[:, None]
        coarse.append(ghost.ravel())
    carrier[real.ravel()] = coarse_real.ravel()[:, None]
    return Refinement(np.concatenate(coarse), carrier)


def subdivide(mesh: Mesh, factor: int) -> tuple[Mesh, Refinement]:
    """Midpoint subdivision, log2(factor) times (factor a power of 2): each triangle cut into
    four at its edges' midpoints; the vertices stay first, midpoints after them (texture
    coordinates interpolated)."""
    require(factor >= 1 and factor & (factor - 1) == 0, "resolution", factor,
            "a power of 2 for a triangle mesh (each refinement halves its edges)")
    vertices, triangles, uvs = mesh.vertices, mesh.triangles, mesh.uvs
    carrier = np.stack([np.arange(mesh.vertex_count)] * 2, axis=1)
    while factor > 1:
        edges, triangles = split_triangles(triangles, len(vertices))
        ends = carrier[edges]                                  # (E, 2 ends, 2)
        points = ends.reshape(len(edges), 4)
        lo, hi = points.min(axis=1), points.max(axis=1)
        same_edge = np.all((points == lo[:, None]) | (points == hi[:, None]), axis=1)
        carrier = np.concatenate([carrier, np.where(same_edge[:, None] & (lo[:, None] != NONE),
                                                    np.stack([lo, hi], axis=1), NONE)])
        vertices = np.concatenate([vertices, vertices[edges].mean(axis=1)])
        uvs = None if uvs is None else np.concatenate([uvs, uvs[edges].mean(axis=1)])
        factor //= 2
    return (Mesh(vertices, triangles, tetrahedra=mesh.tetrahedra, uvs=uvs),
            Refinement(np.arange(mesh.vertex_count), carrier))


def seams_at(pairs: np.ndarray, refinement: Refinement, vertices: np.ndarray) -> np.ndarray:
    """A garment's seam pairs (P, 2) on the subdivided body (subdivide: vertices its refined
    positions): the coarse pairs, and along every coarse edge (i, k) whose ends are sewn to
    j and l, its new points paired in order with those of the coarse edge (j, l), or all
    with j when j = l (an edge eased onto one point)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    coarse = refinement.coarse
    a, b = refinement.carrier.T
    new = np.flatnonzero((a != NONE) & (a != b))
    on_edge = {}
    for v in new:
        on_edge.setdefault((int(min(a[v], b[v])), int(max(a[v], b[v]))), []).append(int(v))
    partners = {}
    for i, j in pairs.tolist():
        partners.setdefault(i, set()).add(j)
        partners.setdefault(j, set()).add(i)

    def along(start: int, end: int) -> list:
        """The new points of coarse edge (start, end), from start to end."""
        points = on_edge.get((min(start, end), max(start, end)), [])
        origin = vertices[coarse[start]]
        return sorted(points, key=lambda v: float(np.sum((vertices[v] - origin) ** 2)))

    refined = [coarse[pairs]]
    for (i, k), points in on_edge.items():
        for j in sorted(partners.get(i, ())):
            for l in sorted(partners.get(k, ())):
                if {j, l} == {i, k}:
                    continue
                if j == l:
                    refined.append(np.column_stack([points, np.full(len(points), coarse[j])]))
                elif (min(j, l), max(j, l)) in on_edge:
                    refined.append(np.column_stack([along(i, k), along(j, l)]))
    return np.unique(np.sort(np.concatenate(refined), axis=1), axis=0)


def springs_at(params: SpringParams | None, factor: int, dimension: int):
    """Constants of springs of a `dimension`-D body refined `factor` times that stand for the
    same modulus, k h^(2 - d) (module doc); None stays None."""
    if params is None or isinstance(params, bool):
        return params
    scale = float(factor) ** (2 - dimension)
    return SpringParams(params.k * scale, params.kd * scale)


def material_at(material, factor: int):
    """A surface's Material or Fabric refined `factor` times: its springs keep their constants
    (a sheet's modulus is k), its hem mass is split f ways."""
    if material.hem_mass == 0 or factor == 1:
        return material
    return replace(material, hem_mass=material.hem_mass / factor)

