"""The candidate pairs of self-collision (self_collision.py), and the kernels that list them.

Candidates (a Verlet list, as molecular dynamics keeps its neighbour lists), made at a step's
end: the vertex-triangle and edge-edge pairs whose boxes swept over the step (the box of their
positions at the step's start and end) meet within `near` = thickness + skin, and which are now
nearer than `near` plus how far they moved relative to each other in the step. That holds every
pair within `near` now and every pair that passed through each other during the step (its
depth on the wrong side is at most its relative motion), however fast it moved: nothing
tunnels between list and contact. The broad phase is a uniform grid of swept boxes
(box_grid.py) with cells for the particles (queried by each triangle's box) and for the edges
(queried by each edge's, f > e), each pair met once. Counted, prefix-summed and written per
triangle and per edge in index order: a fixed list. Pairs within `thickness` in the rest
shape (neighbours through the mesh), and triangles and edges that lost a spring to tearing,
are never listed. The count keeps the first FOUND_KEPT pairs of each triangle and edge, which
the write copies; only one that found more walks the grid again (a dense pile's list took
two walks of about the same time before).
The list is kept while no two particles have moved more than the skin relative to each other
since it was made - their relative motion is at most the diagonal of the bounding box of all
displacements (an exact max/min reduction) - so a pair left out cannot come within `thickness`,
nor pass through, before the list is made again. A body that falls as a whole keeps its list;
one whose parts move apart fast makes one every step.
"""

import numpy as np
import taichi as ti

from ...body.mesh import triangle_edges, unique_rows
from ...geometry import segment_distance, triangle_distance
from ...runtime import backend
from ...runtime.plan import Used
from .box_grid import BLOCK, box_cell, box_cell_count, cell_box, cell_range, first_shared, meets

FOUND_KEPT = 16     # pairs of a triangle or an edge the count keeps for the write


def cloth_edges(cloth) -> tuple[np.ndarray, np.ndarray]:
    """The edges of a cloth's triangles (E, 2), as sorted particle pairs in order, and the
    spring along each (E,), -1 where there is none (a Fabric's): a torn spring's edge no
    longer collides (torn_edge)."""
    triangles = np.asarray(cloth.mesh.triangles, np.int64).reshape(-1, 3)
    if not len(triangles):
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    ends = triangle_edges(triangles)                 # sorted pairs, three per triangle
    edges = unique_rows(ends)
    springs = np.asarray(cloth.triangle_edge_spring, np.int64).reshape(-1, 3)
    n = cloth.particle_count
    rows = np.searchsorted(edges[:, 0] * n + edges[:, 1], ends[:, 0] * n + ends[:, 1])
    along = np.full(len(edges), -1, np.int64)
    np.maximum.at(along, rows, springs.reshape(-1))
    return edges, along


@backend.kernel_argument
class PairList:
    """Room for `capacity` listed pairs: each pair's elements ((vertex, triangle) or (edge,
    edge)), its four particles, whether it is in contact and whether it is near
    (self_collision.py: evaluated in every pass). A bigger list replaces a full one (its
    kernels compile again, once)."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        fields = backend.FieldGroup()
        self.elements = fields.vector(2, ti.i32, capacity)
        self.particles = fields.vector(4, ti.i32, capacity)
        self.active = fields.scalar(ti.i32, capacity)
        self.near = fields.scalar(ti.i32, capacity)
        fields.finalize(self)


def listed(stage, pairs: PairList) -> Used:
    """The pairs in use of `pairs` (the last offset of the stage's pair_start, within the
    list's room), as the count of a loop over them (runtime/plan.py)."""
    return Used(stage.pair_start, stage.triangle_count + stage.edge_count, pairs.capacity)


@backend.kernel
def displacement_box(stage: ti.template(), positions: ti.template(), since: ti.template()
                     ) -> ti.f64:
    """span[0], span[1] = the bounding box of every particle's displacement from `since` to
    `positions`; returns its diagonal [m], the most any two particles moved relative to each
    other. Each block of BLOCK particles is reduced by one thread, then the blocks in order (a
    max and a min are exact in any order; no contended atomics)."""
    for b in range(stage.block_count):
        begin = b * BLOCK
        lo = hi = positions[begin] - since[begin]
        for i in range(begin + 1, ti.min(begin + BLOCK, stage.particle_count)):
            moved = positions[i] - since[i]
            lo, hi = ti.min(lo, moved), ti.max(hi, moved)
        stage.block_span[2 * b] = lo
        stage.block_span[2 * b + 1] = hi
    for _ in range(1):
        stage.span[0], stage.span[1] = stage.block_span[0], stage.block_span[1]
        for b in range(1, stage.block_count):
            stage.span[0] = ti.min(stage.span[0], stage.block_span[2 * b])
            stage.span[1] = ti.max(stage.span[1], stage.block_span[2 * b + 1])
    return ti.cast((stage.span[1] - stage.span[0]).norm(), ti.f64)


@ti.func
def span_middle(stage: ti.template()):
    """The middle of displacement_box's last box: the displacements' common motion."""
    return 0.5 * (stage.span[0] + stage.span[1])


@backend.kernel
def sweep_boxes(stage: ti.template(), state: ti.template()):
    """Each particle's and each edge's box over the step: the box of its positions now and at
    the step's start moved by `shift`, the middle of all particles' displacements in the step
    (span, from displacement_box since the step's start). Moving every start by the same
    vector changes no relative motion - two elements meet at some time in the step in one
    frame exactly when they do in the other - and it shrinks the boxes of a body moving as a
    whole to its motion relative to itself."""
    for _ in range(1):
        stage.shift[None] = span_middle(stage)
    x = ti.static(state.particle_position)
    for i in range(stage.particle_count):
        start = _start(stage, i)
        stage.grid.lo[i] = ti.min(x[i], start)
        stage.grid.hi[i] = ti.max(x[i], start)
    for e in range(stage.edge_count):
        a, b = stage.edges[e][0], stage.edges[e][1]
        stage.grid.lo[stage.particle_count + e] = ti.min(x[a], x[b], _start(stage, a),
                                                         _start(stage, b))
        stage.grid.hi[stage.particle_count + e] = ti.max(x[a], x[b], _start(stage, a),
                                                         _start(stage, b))


@ti.func
def _start(stage: ti.template(), i):
    """Particle i's position at the step's start, moved by the step's common shift."""
    return stage.step_start[i] + stage.shift[None]


@backend.kernel
def mean_edge(stage: ti.template(), state: ti.template()) -> ti.f64:
    """The mean edge length now [m]: summed per block of BLOCK edges, then over the blocks, in
    a fixed order (the same bits on any thread count)."""
    for b in range(stage.edge_block_count):
        total = 0.0
        for e in range(b * BLOCK, ti.min((b + 1) * BLOCK, stage.edge_count)):
            ends = stage.edges[e]
            total += (state.particle_position[ends[0]] - state.particle_position[ends[1]]).norm()
        stage.block_length[b] = total
    for _ in range(1):
        stage.mean_edge[None] = 0.0
        for b in range(stage.edge_block_count):
            stage.mean_edge[None] += stage.block_length[b]
        stage.mean_edge[None] /= ti.max(stage.edge_count, 1)
    return stage.mean_edge[None]


@ti.func
def _moved(stage: ti.template(), state: ti.template(), i, j):
    """How far particles i and j moved relative to each other in this step [m]."""
    return ((state.particle_position[i] - stage.step_start[i])
            - (state.particle_position[j] - stage.step_start[j])).norm()


@ti.func
def _box_gap(lo, hi, other_lo, other_hi):
    """The distance between two boxes (0 if they meet): at most that of anything inside them."""
    return ti.max(other_lo - hi, lo - other_hi, 0.0).norm()


@ti.func
def _joined(model: ti.template(), p, q):
    """Whether particles p and q are one: the same, or sewn together by a seam (their
    Model.particle_weld is the same), which never keep apart."""
    same = p == q
    if ti.static(model.sewn):
        same = model.particle_weld[p] == model.particle_weld[q]
    return same


@ti.func
def _at(model: ti.template(), state: ti.template(), i, rest_shape):
    """Particle i's position now (rest_shape 0) or in the rest shape (1). The distance tests
    run in a loop over the two, so each is compiled once."""
    x = state.particle_position[i]
    if rest_shape:
        x = model.particle_rest_position[i]
    return x


@ti.func
def torn_triangle(stage: ti.template(), state: ti.template(), t):
    """Whether triangle t lost one of its edge springs or, a Fabric's, tore (tearing): it no
    longer collides."""
    springs = stage.triangle_spring[t]
    torn = False
    for k in ti.static(range(3)):
        if springs[k] >= 0 and state.spring_alive[springs[k]] == 0:
            torn = True
    face = stage.triangle_face[t]
    if face >= 0 and state.face_alive[ti.max(face, 0)] == 0:
        torn = True
    return torn


@ti.func
def torn_edge(stage: ti.template(), state: ti.template(), e):
    """Whether edge e's spring tore: it no longer collides."""
    spring = stage.edge_spring[e]
    return spring >= 0 and state.spring_alive[ti.max(spring, 0)] == 0


@ti.func
def torn_pair(stage: ti.template(), state: ti.template(), elements, vertex_triangle):
    """Whether listed pair `elements` ((vertex, triangle) or (edge, edge)) lies beside a tear:
    its triangle, or either edge, no longer collides (torn pieces pass where it was)."""
    torn = False
    if vertex_triangle:
        torn = torn_triangle(stage, state, elements[1])
    else:
        torn = torn_edge(stage, state, elements[0]) or torn_edge(stage, state, elements[1])
    return torn


@ti.func
def _triangle_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                    state: ti.template(), t, near, thickness, write):
    """Vertices v whose box over the step meets triangle t's grown by `near`, nearer to t now
    than `near` + how far v moved relative to t's corners in the step, and farther than
    `thickness` from it in the rest shape (counted, the first FOUND_KEPT kept in `found`, or
    written from pair_start[t] when `write`), in cell order."""
    found = 0
    x = ti.static(state.particle_position)
    tri = stage.triangles[t]
    s0, s1, s2 = _start(stage, tri[0]), _start(stage, tri[1]), _start(stage, tri[2])
    now_lo = ti.min(x[tri[0]], x[tri[1]], x[tri[2]])
    now_hi = ti.max(x[tri[0]], x[tri[1]], x[tri[2]])
    lo = ti.min(now_lo, s0, s1, s2) - near
    hi = ti.max(now_hi, s0, s1, s2) + near
    first, last = cell_box(stage.grid, lo, hi)
    cells = box_cell_count(first, last)
    if torn_triangle(stage, state, t):
        cells = 0
    for k in range(cells):
        cell = box_cell(first, last, k)
        begin, end = cell_range(stage.grid, 0, cell)
        for a in range(begin, end):
            if not meets(stage.grid, a, lo, hi):        # the cell's boxes in turn
                continue
            if not first_shared(stage.grid, a, cell, first):
                continue
            v = stage.grid.cell_item[a]
            if not (_joined(model, v, tri[0]) or _joined(model, v, tri[1])
                    or _joined(model, v, tri[2])):
                moved = ti.max(_moved(stage, state, v, tri[0]), _moved(stage, state, v, tri[1]),
                               _moved(stage, state, v, tri[2]))
                keep = _box_gap(x[v], x[v], now_lo, now_hi) < near + moved   # a cheap bound first
                for shape in range(2):                   # now, then the rest shape
                    if keep:
                        d = triangle_distance(_at(model, state, v, shape),
                                              _at(model, state, tri[0], shape),
                                              _at(model, state, tri[1], shape),
                                              _at(model, state, tri[2], shape))
                        keep = ti.select(shape == 0, d < near + moved, d >= thickness)
                if keep:
                    if write:
                        _write_vertex_pair(stage, pairs, stage.pair_start[t] + found, v, t)
                    elif found < FOUND_KEPT:
                        stage.found[FOUND_KEPT * t + found] = v
                    found += 1
    return found


@ti.func
def _edge_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                state: ti.template(), e, near, thickness, write):
    """Edges f > e sharing no particle with e whose boxes over the step meet e's grown by
    `near`, nearer to e now than `near` + how far their ends moved relative to each other in
    the step, and farther than `thickness` in the rest shape (counted, the first FOUND_KEPT
    kept in `found`, or written from pair_start[T + e])."""
    found = 0
    x = ti.static(state.particle_position)
    ends = stage.edges[e]
    now_lo, now_hi = ti.min(x[ends[0]], x[ends[1]]), ti.max(x[ends[0]], x[ends[1]])
    lo = stage.grid.lo[stage.particle_count + e] - near
    hi = stage.grid.hi[stage.particle_count + e] + near
    first, last = cell_box(stage.grid, lo, hi)
    cells = box_cell_count(first, last)
    if torn_edge(stage, state, e):
        cells = 0
    for k in range(cells):
        cell = box_cell(first, last, k)
        begin, end = cell_range(stage.grid, 1, cell)
        for a in range(begin, end):
            f = stage.grid.cell_item[a] - stage.particle_count
            if f <= e:          # apart: a ti.func in `or` runs whatever the left side
                continue
            if not meets(stage.grid, a, lo, hi):
                continue
            if not first_shared(stage.grid, a, cell, first):
                continue
            other = stage.edges[f]
            if not (_joined(model, other[0], ends[0]) or _joined(model, other[0], ends[1])
                    or _joined(model, other[1], ends[0]) or _joined(model, other[1], ends[1])) \
                    and not torn_edge(stage, state, f):
                moved = ti.max(_moved(stage, state, ends[0], other[0]),
                               _moved(stage, state, ends[0], other[1]),
                               _moved(stage, state, ends[1], other[0]),
                               _moved(stage, state, ends[1], other[1]))
                keep = _box_gap(ti.min(x[other[0]], x[other[1]]),          # a cheap bound first
                                ti.max(x[other[0]], x[other[1]]), now_lo, now_hi) < near + moved
                for shape in range(2):                   # now, then the rest shape
                    if keep:
                        d = segment_distance(_at(model, state, ends[0], shape),
                                             _at(model, state, ends[1], shape),
                                             _at(model, state, other[0], shape),
                                             _at(model, state, other[1], shape))
                        keep = ti.select(shape == 0, d < near + moved, d >= thickness)
                if keep:
                    if write:
                        _write_edge_pair(stage, pairs,
                                         stage.pair_start[stage.triangle_count + e] + found, e, f)
                    elif found < FOUND_KEPT:
                        stage.found[FOUND_KEPT * (stage.triangle_count + e) + found] = f
                    found += 1
    return found


@ti.func
def _write_vertex_pair(stage: ti.template(), pairs: ti.template(), slot, v, t):
    tri = stage.triangles[t]
    pairs.elements[slot] = ti.Vector([v, t])
    pairs.particles[slot] = ti.Vector([v, tri[0], tri[1], tri[2]])


@ti.func
def _write_edge_pair(stage: ti.template(), pairs: ti.template(), slot, e, f):
    ends, other = stage.edges[e], stage.edges[f]
    pairs.elements[slot] = ti.Vector([e, f])
    pairs.particles[slot] = ti.Vector([ends[0], ends[1], other[0], other[1]])


@backend.kernel
def list_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                state: ti.template(), near: float, thickness: float, write: ti.i32):
    """Count (write = 0: pair_start[1 + t] = the pairs of triangle t, pair_start[1 + T + e] =
    of edge e, the first FOUND_KEPT of each kept in `found`) or, after the prefix sum, write
    them (write = 1: copied from `found`, or found again by a triangle or edge with more).
    One kernel for both: it is the largest kernel self-collision compiles."""
    for t in range(stage.triangle_count):
        begin, end = 0, 0
        if write:       # offsets once prefix-summed (the count writes them in parallel)
            begin, end = stage.pair_start[t], stage.pair_start[t + 1]
        if not write or end - begin > FOUND_KEPT:
            found = _triangle_pairs(stage, pairs, model, state, t, near, thickness, write)
            if not write:
                stage.pair_start[t + 1] = found
        else:
            for k in range(end - begin):
                _write_vertex_pair(stage, pairs, begin + k, stage.found[FOUND_KEPT * t + k], t)
    for e in range(stage.edge_count):
        k = stage.triangle_count + e
        begin, end = 0, 0
        if write:       # offsets once prefix-summed (the count writes them in parallel)
            begin, end = stage.pair_start[k], stage.pair_start[k + 1]
        if not write or end - begin > FOUND_KEPT:
            found = _edge_pairs(stage, pairs, model, state, e, near, thickness, write)
            if not write:
                stage.pair_start[k + 1] = found
        else:
            for j in range(end - begin):
                _write_edge_pair(stage, pairs, begin + j, e, stage.found[FOUND_KEPT * k + j])


@backend.kernel
def prefix_pairs(stage: ti.template()) -> ti.i32:
    """Inclusive prefix sum of the counts (serial): pair_start becomes offsets; the total."""
    stage.pair_start[0] = 0
    for _ in range(1):
        for k in range(stage.triangle_count + stage.edge_count):
            stage.pair_start[k + 1] += stage.pair_start[k]
    return stage.pair_start[stage.triangle_count + stage.edge_count]
