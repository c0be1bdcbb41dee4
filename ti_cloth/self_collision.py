"""Self-collision and cloth-on-cloth contact (issue 18): after every step, no particle stays
closer than `thickness` to a triangle it is not a corner of, nor an edge closer than `thickness`
to an edge it shares no particle with, across every body of the simulation.

Each contact pass:
1. Broad phase (particle_grid.py): the particles sorted into cells of side L + thickness,
   L the longest edge now, so every triangle within `thickness` of a particle has a corner in
   the 3 x 3 x 3 block of cells around it, and every edge within `thickness` of an edge has an
   end in the block around one of the edge's ends.
2. Narrow phase, per particle (vertex-triangle) and per edge (edge-edge), in parallel, counted
   first and then written at offsets from a prefix sum of the counts: a fixed, index-ordered
   list of contacts. A pair is found from one side only (the vertex; the lower-numbered edge)
   and through one corner of the other (the first one within reach; for edges, the first pair
   of ends within reach), so it is listed once.
   - vertex v and triangle t: v's foot on t's plane inside t, and v's height over t, measured
     on the side v was on at the start of the step, below `thickness` (a vertex that crossed
     the plane during the step is caught and pushed back to the side it came from);
   - edges e and f: the closest points of the two segments (interior to both) nearer than
     `thickness`, or on the other side of each other than at the step's start.
   Pairs closer than `thickness` in the rest shape (neighbours through the mesh) are skipped.
3. Response: each contact is the one-sided constraint C = distance - thickness >= 0 with
   gradient g_k n on its four particles (vertex 1, corners -w; edges (1 - s, s, -(1 - t), -t)),
   projected mass-weighted as a position-based constraint: particle k moves by
   -C w_k g_k n / sum_j w_j g_j^2. Each particle gathers its contacts' moves in list order and
   takes their mean (Jacobi with averaging: many contacts on one particle do not add up to an
   overshoot). No float atomics, so reruns and thread counts give the same bits.
Velocities follow the positions' correction (v += dx / h), as after strain limiting.
"""

import hashlib
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, limits
from ._validate import count, finite_number, require
from .forces import altitude_frame
from .mesh import triangle_edges, unique_rows
from .particle_grid import ParticleGrid, cell_block, cell_range
from .state import copy_positions
from .transfer import upload

PAIRS_PER_PARTICLE = 8      # contact list capacity, per particle
INSIDE = 1e-6               # a foot this far outside a triangle (in barycentric terms) is inside


@dataclass(frozen=True)
class SelfCollision:
    """thickness: the distance [m] kept between a particle and any triangle it is not a corner
    of, and between edges that share no particle, > 0 (Blender's self_distance_min, 0.015 m).
    iterations: contact passes per step (broad phase, narrow phase, response), >= 1."""

    thickness: float = 0.005
    iterations: int = 2

    def __post_init__(self):
        thickness = finite_number("SelfCollision.thickness", self.thickness, 0.0, strict=True,
                                  unit="m")
        require(thickness <= limits.LENGTH.high, "SelfCollision.thickness", thickness,
                f"in (0, {limits.LENGTH.high:g}] m")
        object.__setattr__(self, "thickness", thickness)
        object.__setattr__(self, "iterations", count("SelfCollision.iterations", self.iterations,
                                                     limits.ITERATIONS))


@backend.kernel_argument
class SelfContact:
    """The self-collision stage of one simulation: the body's triangles and edges, each
    particle's triangles and edges (CSR), the grid, the contact list and the positions at the
    start of the step."""

    def __init__(self, settings: SelfCollision, cloth):
        n = cloth.particle_count
        triangles = np.asarray(cloth.mesh.triangles, np.int64).reshape(-1, 3)
        edges = (unique_rows(np.sort(triangle_edges(triangles), axis=1)) if len(triangles)
                 else np.zeros((0, 2), np.int64))
        self.particle_count = n
        self.triangle_count = len(triangles)
        self.edge_count = len(edges)
        self.capacity = PAIRS_PER_PARTICLE * max(n, 1)
        real = backend.real()
        fields = backend.FieldGroup()
        self.triangles = fields.vector(3, ti.i32, max(len(triangles), 1))
        self.edges = fields.vector(2, ti.i32, max(len(edges), 1))
        self.triangle_start = fields.scalar(ti.i32, n + 1)
        self.particle_triangle = fields.scalar(ti.i32, max(3 * len(triangles), 1))
        self.edge_start = fields.scalar(ti.i32, n + 1)
        self.particle_edge = fields.scalar(ti.i32, max(2 * len(edges), 1))
        self.step_start = fields.vector(3, real, n)
        self.before = fields.vector(3, real, n)
        self.reach = fields.scalar(real, ())
        self.pair_start = fields.scalar(ti.i32, n + len(edges) + 1)
        self.pair_particles = fields.vector(4, ti.i32, self.capacity)
        self.pair_move = fields.vector(3, real, 4 * self.capacity)
        self.contact_start = fields.scalar(ti.i32, n + 1)
        self.contact_fill = fields.scalar(ti.i32, n)
        self.contact = fields.scalar(ti.i32, 4 * self.capacity)
        fields.finalize(self)
        self.grid = ParticleGrid(n)
        self.load(settings, cloth)
        upload(((self.triangles, triangles), (self.edges, edges),
                *_incidence(self.triangle_start, self.particle_triangle, triangles, n),
                *_incidence(self.edge_start, self.particle_edge, edges, n)))

    @staticmethod
    def structure(settings: SelfCollision, cloth) -> tuple:
        triangles = np.ascontiguousarray(cloth.mesh.triangles).tobytes()
        return ("SelfContact", cloth.particle_count,
                hashlib.blake2b(triangles, digest_size=16).hexdigest())

    def load(self, settings: SelfCollision, cloth) -> None:
        require(isinstance(settings, SelfCollision), "self_collision", settings,
                "None or a SelfCollision")
        self.settings = settings

    def before_step(self, state, t: float) -> None:
        copy_positions(state, self.step_start)

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The self-collision stage of a step ending at time t (simulation.STEP_ORDER)."""
        if self.triangle_count == 0:
            return
        thickness = self.settings.thickness
        copy_positions(state, self.before)
        for _ in range(self.settings.iterations):
            _longest_edge(self, state)
            self.grid.build(state.particle_position, float(self.reach[None]) + thickness)
            _count_contacts(self, model, state, thickness)
            total = _prefix(self)
            if total > self.capacity:
                raise RuntimeError(
                    f"self-collision found {total} contacts in step {step_index}, more than its "
                    f"{self.capacity} slots ({PAIRS_PER_PARTICLE} per particle): the cloth is "
                    "crushed far below its thickness; use more substeps or a smaller thickness")
            if total == 0:
                break
            _write_contacts(self, model, state, thickness)
            _index_contacts(self)
            _apply_contacts(self, model, state)
        _follow(self, state, dt)


def _incidence(start_field, list_field, elements: np.ndarray, n: int):
    """(field, values) pairs of a CSR from particles to the elements (rows) they belong to, in
    element order."""
    owners = elements.ravel()
    order = np.argsort(owners, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(owners, minlength=n))])
    return (start_field, start), (list_field, order // elements.shape[1] if len(owners) else order)


@ti.kernel
def _longest_edge(stage: ti.template(), state: ti.template()):
    """reach = the longest edge now [m] (a max: exact in any order)."""
    stage.reach[None] = 0.0
    for e in range(stage.edge_count):
        ends = stage.edges[e]
        ti.atomic_max(stage.reach[None],
                      (state.particle_position[ends[0]] - state.particle_position[ends[1]]).norm())


@ti.func
def _segments(p1, q1, p2, q2):
    """Parameters (s, t) of the closest points p1 + s (q1 - p1), p2 + t (q2 - p2) of two
    segments of non-zero length (Ericson, Real-Time Collision Detection, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1.dot(d1), d2.dot(d2), d2.dot(r)
    c, b = d1.dot(r), d1.dot(d2)
    denominator = a * e - b * b
    s = 0.0
    if denominator > 1e-12 * a * e:
        s = ti.math.clamp((b * f - c * e) / denominator, 0.0, 1.0)
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = ti.math.clamp(-c / a, 0.0, 1.0)
    elif t > 1.0:
        t = 1.0
        s = ti.math.clamp((b - c) / a, 0.0, 1.0)
    return s, t


@ti.func
def _vertex_triangle(stage: ti.template(), positions: ti.template(), start: ti.template(), v, t,
                     thickness):
    """(in contact, n, gap, w) of vertex v and triangle t at `positions`, the side taken from
    `start`: n the unit normal towards v's side at the start, gap = v's height over the plane
    along n minus thickness (< 0 in contact), w the barycentric coordinates of v's foot."""
    tri = stage.triangles[t]
    n, h, w = altitude_frame(positions[v], positions[tri[0]], positions[tri[1]], positions[tri[2]])
    n0, h0, _ = altitude_frame(start[v], start[tri[0]], start[tri[1]], start[tri[2]])
    side = ti.select(h0 >= 0.0, 1.0, -1.0)
    if n.dot(n0) < 0.0:
        side = -side                                 # the triangle turned over in the step
    gap = side * h - thickness
    inside = w.min() >= -INSIDE and n.norm() > 0
    return inside and gap < 0.0 and gap > -stage.reach[None] - thickness, side * n, gap, w


@ti.func
def _edge_edge(stage: ti.template(), positions: ti.template(), start: ti.template(), e, f,
               thickness):
    """(in contact, n, gap, s, t) of edges e and f: closest points at parameters s on e and t
    on f, n the unit direction from f's point to e's on the side e was at the start of the
    step, gap = distance along n minus thickness."""
    a, b = stage.edges[e][0], stage.edges[e][1]
    c, d = stage.edges[f][0], stage.edges[f][1]
    s, t = _segments(positions[a], positions[b], positions[c], positions[d])
    between = (positions[a] + s * (positions[b] - positions[a])
               - positions[c] - t * (positions[d] - positions[c]))
    s0, t0 = _segments(start[a], start[b], start[c], start[d])
    before = start[a] + s0 * (start[b] - start[a]) - start[c] - t0 * (start[d] - start[c])
    distance = between.norm()
    n = between / ti.max(distance, 1e-30)
    if before.norm() > 0 and between.dot(before) < 0.0:
        n = -n                                       # crossed during the step: back to its side
    if distance == 0.0:
        n = before / ti.max(before.norm(), 1e-30)
    gap = between.dot(n) - thickness
    interior = s > 0.0 and s < 1.0 and t > 0.0 and t < 1.0
    return interior and gap < 0.0 and n.norm() > 0, n, gap, s, t


@ti.func
def _near_box(x, a, b, c, margin):
    """Whether x is within `margin` of the bounding box of a, b, c (a cheap test first)."""
    lo, hi = ti.min(a, b, c) - margin, ti.max(a, b, c) + margin
    return (x >= lo).all() and (x <= hi).all()


@ti.func
def _boxes_near(a, b, c, d, margin):
    """Whether the bounding boxes of segments ab and cd are within `margin` of each other."""
    return ((ti.min(a, b) - margin <= ti.max(c, d)).all()
            and (ti.min(c, d) - margin <= ti.max(a, b)).all())


@ti.func
def _rest_close(model: ti.template(), corners, weights, thickness):
    """Whether the pair (corners, gradient weights: sum_k g_k x_k is its separation) is within
    thickness in the rest shape."""
    separation = ti.Vector([0.0, 0.0, 0.0])
    for k in ti.static(range(4)):
        separation += weights[k] * model.particle_rest_position[corners[k]]
    return separation.norm() < thickness


@ti.func
def _contact_move(model: ti.template(), stage: ti.template(), slot, corners, weights, n, gap):
    """Write the position-based projection of one contact: particle k of `corners` moves by
    -gap w_k g_k n / sum_j w_j g_j^2 (pair_move[4 slot + k])."""
    norm = 0.0
    for k in ti.static(range(4)):
        norm += model.particle_inv_mass[corners[k]] * weights[k] * weights[k]
    scale = 0.0
    if norm > 0:
        scale = -gap / norm
    stage.pair_particles[slot] = corners
    for k in ti.static(range(4)):
        stage.pair_move[4 * slot + k] = scale * model.particle_inv_mass[corners[k]] * weights[k] * n


@ti.func
def _vertex_contacts(stage: ti.template(), model: ti.template(), state: ti.template(), v,
                     thickness, write: ti.template()):
    """Contacts of vertex v with triangles (counted, or written from pair_start[v] when
    `write`): each triangle is reached through its first corner within reach of v."""
    found = 0
    x = state.particle_position[v]
    reach = stage.reach[None] + thickness
    lo, hi = cell_block(stage.grid, x)
    for cz in range(lo[2], hi[2] + 1):
        for cy in range(lo[1], hi[1] + 1):
            for cx in range(lo[0], hi[0] + 1):
                begin, end = cell_range(stage.grid, ti.Vector([cx, cy, cz]))
                for a in range(begin, end):
                    j = stage.grid.cell_particle[a]
                    if (state.particle_position[j] - x).norm() <= reach:
                        for k in range(stage.triangle_start[j], stage.triangle_start[j + 1]):
                            t = stage.particle_triangle[k]
                            tri = stage.triangles[t]
                            first = -1
                            for c in ti.static(range(3)):
                                if first < 0 and (state.particle_position[tri[c]] - x).norm() <= reach:
                                    first = tri[c]
                            if (first == j and v != tri[0] and v != tri[1] and v != tri[2]
                                    and _near_box(x, state.particle_position[tri[0]],
                                                  state.particle_position[tri[1]],
                                                  state.particle_position[tri[2]], thickness)):
                                touching, n, gap, w = _vertex_triangle(
                                    stage, state.particle_position, stage.step_start, v, t, thickness)
                                corners = ti.Vector([v, tri[0], tri[1], tri[2]])
                                weights = ti.Vector([1.0, -w[0], -w[1], -w[2]])
                                if touching and not _rest_close(model, corners, weights, thickness):
                                    if ti.static(write):
                                        _contact_move(model, stage, stage.pair_start[v] + found,
                                                      corners, weights, n, gap)
                                    found += 1
    return found


@ti.func
def _first_close_ends(positions: ti.template(), ends, other, reach):
    """The first pair of ends (one of each edge) within reach of each other, in the order
    (e0, f0), (e0, f1), (e1, f0), (e1, f1); (-1, -1) if none."""
    first, second = -1, -1
    for p in ti.static(range(2)):
        for q in ti.static(range(2)):
            if first < 0 and (positions[ends[p]] - positions[other[q]]).norm() <= reach:
                first, second = ends[p], other[q]
    return first, second


@ti.func
def _edge_contacts(stage: ti.template(), model: ti.template(), state: ti.template(), e,
                   thickness, write: ti.template()):
    """Contacts of edge e with edges f > e sharing no particle with it (counted, or written
    from pair_start[N + e]). Two edges within thickness have an end each within
    L + thickness of each other (each closest point is within L / 2 of an end): f is found
    from each end of e through the particles within that reach, and kept from the first such
    pair of ends only (_first_close_ends)."""
    found = 0
    ends = stage.edges[e]
    reach = stage.reach[None] + thickness
    for p in range(2):
        mine = ti.select(p == 0, ends[0], ends[1])
        x = state.particle_position[mine]
        lo, hi = cell_block(stage.grid, x)
        for cz in range(lo[2], hi[2] + 1):
            for cy in range(lo[1], hi[1] + 1):
                for cx in range(lo[0], hi[0] + 1):
                    begin, end = cell_range(stage.grid, ti.Vector([cx, cy, cz]))
                    for a in range(begin, end):
                        j = stage.grid.cell_particle[a]
                        if (state.particle_position[j] - x).norm() <= reach:
                            for k in range(stage.edge_start[j], stage.edge_start[j + 1]):
                                f = stage.particle_edge[k]
                                other = stage.edges[f]
                                shared = (other[0] == ends[0] or other[0] == ends[1]
                                          or other[1] == ends[0] or other[1] == ends[1])
                                if f > e and not shared:
                                    first, second = _first_close_ends(state.particle_position,
                                                                      ends, other, reach)
                                    if first == mine and second == j and _boxes_near(
                                            state.particle_position[ends[0]],
                                            state.particle_position[ends[1]],
                                            state.particle_position[other[0]],
                                            state.particle_position[other[1]], thickness):
                                        touching, n, gap, s, t = _edge_edge(
                                            stage, state.particle_position, stage.step_start, e,
                                            f, thickness)
                                        corners = ti.Vector([ends[0], ends[1], other[0], other[1]])
                                        weights = ti.Vector([1.0 - s, s, t - 1.0, -t])
                                        if touching and not _rest_close(model, corners, weights,
                                                                        thickness):
                                            if ti.static(write):
                                                _contact_move(model, stage, stage.pair_start[
                                                    stage.particle_count + e] + found, corners,
                                                    weights, n, gap)
                                            found += 1
    return found


@ti.kernel
def _count_contacts(stage: ti.template(), model: ti.template(), state: ti.template(),
                    thickness: float):
    """pair_start[1 + v] = contacts of vertex v, pair_start[1 + N + e] = of edge e."""
    for v in range(stage.particle_count):
        stage.pair_start[v + 1] = _vertex_contacts(stage, model, state, v, thickness, False)
    for e in range(stage.edge_count):
        stage.pair_start[stage.particle_count + e + 1] = _edge_contacts(
            stage, model, state, e, thickness, False)


@ti.kernel
def _prefix(stage: ti.template()) -> ti.i32:
    """Inclusive prefix sum of the counts (serial): pair_start becomes offsets; the total."""
    stage.pair_start[0] = 0
    for _ in range(1):
        for k in range(stage.particle_count + stage.edge_count):
            stage.pair_start[k + 1] += stage.pair_start[k]
    return stage.pair_start[stage.particle_count + stage.edge_count]


@ti.kernel
def _write_contacts(stage: ti.template(), model: ti.template(), state: ti.template(),
                    thickness: float):
    for v in range(stage.particle_count):
        if stage.pair_start[v + 1] > stage.pair_start[v]:
            _vertex_contacts(stage, model, state, v, thickness, True)
    for e in range(stage.edge_count):
        k = stage.particle_count + e
        if stage.pair_start[k + 1] > stage.pair_start[k]:
            _edge_contacts(stage, model, state, e, thickness, True)


@ti.kernel
def _index_contacts(stage: ti.template()):
    """contact[contact_start[i]:contact_start[i + 1]] = the slots 4 p + k at which contact p
    moves particle i, in contact order (counts, prefix sum and fill all serial)."""
    total = stage.pair_start[stage.particle_count + stage.edge_count]
    for _ in range(1):
        for i in range(stage.particle_count + 1):
            stage.contact_start[i] = 0
        for p in range(total):
            for k in ti.static(range(4)):
                stage.contact_start[stage.pair_particles[p][k] + 1] += 1
        for i in range(stage.particle_count):
            stage.contact_start[i + 1] += stage.contact_start[i]
            stage.contact_fill[i] = stage.contact_start[i]
        for p in range(total):
            for k in ti.static(range(4)):
                i = stage.pair_particles[p][k]
                stage.contact[stage.contact_fill[i]] = 4 * p + k
                stage.contact_fill[i] += 1


@ti.kernel
def _apply_contacts(stage: ti.template(), model: ti.template(), state: ti.template()):
    """Each particle moves by the mean of its contacts' moves, gathered in contact order."""
    for i in range(stage.particle_count):
        begin, end = stage.contact_start[i], stage.contact_start[i + 1]
        if end > begin and model.particle_inv_mass[i] > 0:
            move = ti.Vector([0.0, 0.0, 0.0])
            for a in range(begin, end):
                move += stage.pair_move[stage.contact[a]]
            state.particle_position[i] += move / (end - begin)


@ti.kernel
def _follow(stage: ti.template(), state: ti.template(), dt: float):
    """Velocities follow the contact corrections of this stage (v += dx / h)."""
    for i in range(stage.particle_count):
        x = state.particle_position[i]
        state.particle_velocity[i] += (x - stage.before[i]) / dt
