"""Self-collision and cloth-on-cloth contact (issue 18): after every step, no particle stays
closer than `thickness` to a triangle it is not a corner of, nor an edge closer than `thickness`
to an edge it shares no particle with, across every body of the simulation.

Candidates (a Verlet list, as molecular dynamics keeps its neighbour lists), made at a step's
end: the vertex-triangle and edge-edge pairs whose boxes swept over the step (the box of their
positions at the step's start and end) meet within `near` = thickness + skin, and which are now
nearer than `near` plus how far they moved relative to each other in the step. That holds every
pair within `near` now and every pair that passed through each other during the step (its
depth on the wrong side is at most its relative motion), however fast it moved: nothing
tunnels between list and contact. The broad phase is a uniform grid of swept boxes
(box_grid.py) with cells for the particles (queried by each triangle's box) and for the edges
(queried by each edge's, f > e), each pair met once. Counted, prefix-summed and written per triangle and
per edge in index order: a fixed list. Pairs within `thickness` in the rest shape (neighbours
through the mesh) are never listed.
The list is kept while no two particles have moved more than the skin relative to each other
since it was made - their relative motion is at most the diagonal of the bounding box of all
displacements (an exact max/min reduction) - so a pair left out cannot come within `thickness`,
nor pass through, before the list is made again. A body that falls as a whole keeps its list;
one whose parts move apart fast makes one every step.

Each contact pass evaluates every listed pair:
- vertex v and triangle t: v's foot on t's plane inside t, and v's height over t, measured on
  the side v was on at the start of the step, below `thickness` (a vertex that crossed the plane
  during the step is pushed back to the side it came from);
- edges e and f: the closest points of the two segments, interior to both, nearer than
  `thickness` or on the other side of each other than at the step's start.
Each contact is the one-sided constraint C = distance - thickness >= 0 with gradient g_k n on
its four particles (vertex 1, corners -w; edges (1 - s, s, -(1 - t), -t)), projected
mass-weighted as a position-based constraint: particle k moves by -w_k g_k (C n + f) / W,
W = sum_j w_j g_j^2, where f is the Coulomb friction correction: the tangential relative motion
of the two contact points over the step, removed entirely when it is at most
friction x penetration depth, shortened by that much otherwise (as the colliders do). Each
particle gathers its contacts' moves in list order and takes their mean (Jacobi with averaging:
many contacts on one particle do not add up to an overshoot). No float atomics except exact
max/min, so reruns and thread counts give the same bits. Velocities follow the positions'
correction (v += dx / h), as after strain limiting.

Strings and hair (no triangles) do not take part.
"""

import hashlib
import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, limits
from ._validate import count, finite_number, require
from .forces import altitude_frame
from .mesh import triangle_edges, unique_rows
from .colliders import project_out
from .box_grid import (BLOCK, BoxGrid, box_cell, box_cell_count, cell_box, cell_range,
                       found_here)
from .proximity import segment_distance, segment_parameters, triangle_distance
from .state import copy_positions
from .transfer import upload

PAIRS_PER_PARTICLE = 32     # candidate list room at first, per particle
MAX_PAIRS_PER_PARTICLE = 256
SKIN = 1.0                  # the list's slack (skin), in thicknesses
THICK = 0.5                 # a thickness above this (in mean rest edges) is warned about
RESOLVED = 0.01             # a contact shallower than this (in thicknesses) ends the passes
INSIDE = 1e-6               # a foot this far outside a triangle (in barycentric terms) is inside


@dataclass(frozen=True)
class SelfCollision:
    """thickness: the distance [m] kept between a particle and any triangle it is not a corner
    of, and between edges that share no particle, > 0 (Blender's self_distance_min, 0.015 m).
    friction: Coulomb coefficient between touching layers, >= 0.
    iterations: contact passes per step at most, >= 1; they stop once no contact is deeper
    than 1 % of the thickness."""

    thickness: float = 0.005
    friction: float = 0.0
    iterations: int = 16

    def __post_init__(self):
        thickness = finite_number("SelfCollision.thickness", self.thickness, 0.0, strict=True,
                                  unit="m")
        require(thickness <= limits.LENGTH.high, "SelfCollision.thickness", thickness,
                f"in (0, {limits.LENGTH.high:g}] m")
        object.__setattr__(self, "thickness", thickness)
        object.__setattr__(self, "friction", finite_number("SelfCollision.friction",
                                                           self.friction, 0.0))
        object.__setattr__(self, "iterations", count("SelfCollision.iterations", self.iterations,
                                                     limits.ITERATIONS))


@dataclass(frozen=True)
class SelfContacts:
    """Pairs of a simulation's self-collision (Simulation.self_contacts): vertex_triangle
    (K, 2) rows (vertex, triangle index into the mesh), edge_edge (M, 2) rows of edge
    indices into `edges` (E, 2) particle pairs."""

    vertex_triangle: np.ndarray
    edge_edge: np.ndarray
    edges: np.ndarray


def warn_if_thick(settings: SelfCollision, cloth) -> None:
    """Warn when the thickness exceeds THICK x the mean rest edge of the cloth's triangles."""
    triangles = np.asarray(cloth.mesh.triangles).reshape(-1, 3)
    if not len(triangles):
        return
    rest = cloth.particle_position
    mean = float(np.linalg.norm(rest[triangles] - rest[np.roll(triangles, 1, axis=1)],
                                axis=2).mean())
    if settings.thickness > THICK * mean:
        warnings.warn(
            f"SelfCollision.thickness {settings.thickness:g} m is more than {THICK:g} x the "
            f"mean rest edge ({mean:.3g} m): pairs of the mesh that are neighbours but farther "
            "apart than the thickness at rest touch as soon as the cloth wrinkles - it "
            "stiffens, and each step costs many contact passes. Use a thickness below "
            f"{THICK * mean:.3g} m or a coarser mesh", stacklevel=3)


@backend.kernel_argument
class SelfContact:
    """The self-collision stage of one simulation: the body's triangles and edges, each
    particle's edges (CSR), the grid, the candidate list and the positions at the start of the
    step and at the list's making."""

    def __init__(self, settings: SelfCollision, cloth):
        n = cloth.particle_count
        triangles = np.asarray(cloth.mesh.triangles, np.int64).reshape(-1, 3)
        edges = (unique_rows(np.sort(triangle_edges(triangles), axis=1)) if len(triangles)
                 else np.zeros((0, 2), np.int64))
        self.particle_count = n
        self.triangle_count = len(triangles)
        self.edge_count = len(edges)
        self.edge_rows = edges
        real = backend.real()
        fields = backend.FieldGroup()
        self.triangles = fields.vector(3, ti.i32, max(len(triangles), 1))
        self.edges = fields.vector(2, ti.i32, max(len(edges), 1))
        self.step_start = fields.vector(3, real, n)
        self.before = fields.vector(3, real, n)
        self.listed_at = fields.vector(3, real, n)
        self.block_count = -(-n // BLOCK)
        self.edge_block_count = max(-(-len(edges) // BLOCK), 1)
        self.block_span = fields.vector(3, real, 2 * self.block_count)
        self.span = fields.vector(3, real, 2)      # the box of the displacements since listing
        self.shift = fields.vector(3, real, ())    # the middle of the displacements in the step
        self.block_length = fields.scalar(real, self.edge_block_count)
        self.mean_edge = fields.scalar(real, ())
        self.pair_start = fields.scalar(ti.i32, len(triangles) + len(edges) + 1)
        self.touching = fields.vector(2, ti.i32, ())
        self.contact_start = fields.scalar(ti.i32, n + 1)
        self.contact_fill = fields.scalar(ti.i32, n)
        fields.finalize(self)
        self.grid = BoxGrid(n, len(edges))         # particles, then edges
        self.candidates = PairList(PAIRS_PER_PARTICLE * max(n, 1))
        self.load(settings, cloth)
        upload(((self.triangles, triangles), (self.edges, edges)))

    @staticmethod
    def structure(settings: SelfCollision, cloth) -> tuple:
        triangles = np.ascontiguousarray(cloth.mesh.triangles).tobytes()
        return ("SelfContact", cloth.particle_count,
                hashlib.blake2b(triangles, digest_size=16).hexdigest())

    def load(self, settings: SelfCollision, cloth) -> None:
        require(isinstance(settings, SelfCollision), "self_collision", settings,
                "None or a SelfCollision")
        self.settings = settings
        self.colliders = None
        self.forget()

    def attach(self, colliders) -> None:
        """The simulation's ColliderSet (or None): each contact pass ends by projecting the
        particles out of the colliders again, so a pile on the ground is not pushed into it."""
        self.colliders = colliders

    def forget(self) -> None:
        """Drop the candidate list: the next step makes a new one (after a restart)."""
        self.listed = False
        self.pair_total = self.vertex_pairs = 0

    def before_step(self, state, t: float) -> None:
        copy_positions(state, self.step_start)

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The self-collision stage of a step ending at time t (simulation.STEP_ORDER)."""
        if self.triangle_count == 0:
            return
        thickness = self.settings.thickness
        if not self.listed or _moved_since_listed(self, state) > SKIN * thickness:
            self._make_list(model, state, step_index)
        if self.pair_total == 0:
            return
        copy_positions(state, self.before)
        for _ in range(self.settings.iterations):
            touching, deep = _evaluate(self, self.candidates, model, state, thickness,
                                       self.settings.friction)
            if touching == 0:
                break
            _apply_contacts(self, self.candidates, model, state)
            if self.colliders is not None:
                project_out(model, state, self.colliders)
            if deep == 0:
                break
        _follow(self, state, dt)

    def _make_list(self, model, state, step_index: int) -> None:
        """List the pairs that met within thickness + skin during the step (their swept boxes
        meet) and are now nearer than that plus how far they moved relative to each other."""
        near = (1.0 + SKIN) * self.settings.thickness
        _sweep_boxes(self, state)
        cell = float(_mean_edge(self, state)) + 2.0 * near       # about a query's size
        self.grid.build(cell)
        _list_pairs(self, self.candidates, model, state, near, self.settings.thickness, 0)
        total = _prefix(self)
        if total > self.candidates.capacity:
            if total > MAX_PAIRS_PER_PARTICLE * self.particle_count:
                raise RuntimeError(
                    f"self-collision found {total} pairs within {near:.3g} m in step "
                    f"{step_index}, more than {MAX_PAIRS_PER_PARTICLE} per particle: the cloth "
                    "is crushed far below its thickness; use more substeps or a smaller "
                    "thickness")
            self.candidates = PairList(min(2 * total,
                                           MAX_PAIRS_PER_PARTICLE * self.particle_count))
        _list_pairs(self, self.candidates, model, state, near, self.settings.thickness, 1)
        _index_contacts(self, self.candidates)
        copy_positions(state, self.listed_at)
        self.listed, self.pair_total = True, total
        self.vertex_pairs = int(self.pair_start[self.triangle_count])

    def pairs(self, active: bool = True) -> SelfContacts:
        """The listed candidate pairs, or (active) those in contact in the last pass of the
        last step."""
        total = self.pair_total
        kept = np.arange(total)
        if active:
            kept = kept[self.candidates.active.to_numpy()[:total] > 0]
        elements = self.candidates.elements.to_numpy()[kept]
        vertex = kept < self.vertex_pairs
        return SelfContacts(elements[vertex], elements[~vertex], self.edge_rows)


@backend.kernel_argument
class PairList:
    """Room for `capacity` listed pairs: each pair's elements ((vertex, triangle) or (edge,
    edge)), its four particles, whether it is in contact and its four particles' moves; and
    per particle, the slots 4 p + k that move it (contact, indexed by the stage's
    contact_start). A bigger list replaces a full one (its kernels compile again, once)."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        real = backend.real()
        fields = backend.FieldGroup()
        self.elements = fields.vector(2, ti.i32, capacity)
        self.particles = fields.vector(4, ti.i32, capacity)
        self.active = fields.scalar(ti.i32, capacity)
        self.move = fields.vector(3, real, 4 * capacity)
        self.contact = fields.scalar(ti.i32, 4 * capacity)
        fields.finalize(self)


@ti.kernel
def _moved_since_listed(stage: ti.template(), state: ti.template()) -> ti.f64:
    """The diagonal of the bounding box of every particle's displacement since the list was
    made [m]: the most any two particles moved relative to each other. Each block of BLOCK
    particles is reduced by one thread, then the blocks in order (a max and a min are exact in
    any order; no contended atomics)."""
    for b in range(stage.block_count):
        begin = b * BLOCK
        lo = hi = state.particle_position[begin] - stage.listed_at[begin]
        for i in range(begin + 1, ti.min(begin + BLOCK, stage.particle_count)):
            moved = state.particle_position[i] - stage.listed_at[i]
            lo, hi = ti.min(lo, moved), ti.max(hi, moved)
        stage.block_span[2 * b] = lo
        stage.block_span[2 * b + 1] = hi
    for _ in range(1):
        stage.span[0], stage.span[1] = stage.block_span[0], stage.block_span[1]
        for b in range(1, stage.block_count):
            stage.span[0] = ti.min(stage.span[0], stage.block_span[2 * b])
            stage.span[1] = ti.max(stage.span[1], stage.block_span[2 * b + 1])
    return ti.cast((stage.span[1] - stage.span[0]).norm(), ti.f64)


@ti.kernel
def _sweep_boxes(stage: ti.template(), state: ti.template()):
    """Each particle's and each edge's box over the step: the box of its positions now and at
    the step's start moved by `shift`, the middle of all particles' displacements in the step.
    Moving every start by the same vector changes no relative motion - two elements meet at
    some time in the step in one frame exactly when they do in the other - and it shrinks the
    boxes of a body moving as a whole to its motion relative to itself."""
    for b in range(stage.block_count):
        begin = b * BLOCK
        lo = hi = state.particle_position[begin] - stage.step_start[begin]
        for i in range(begin + 1, ti.min(begin + BLOCK, stage.particle_count)):
            moved = state.particle_position[i] - stage.step_start[i]
            lo, hi = ti.min(lo, moved), ti.max(hi, moved)
        stage.block_span[2 * b] = lo
        stage.block_span[2 * b + 1] = hi
    for _ in range(1):
        lo, hi = stage.block_span[0], stage.block_span[1]
        for b in range(1, stage.block_count):
            lo = ti.min(lo, stage.block_span[2 * b])
            hi = ti.max(hi, stage.block_span[2 * b + 1])
        stage.shift[None] = 0.5 * (lo + hi)
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


@ti.kernel
def _mean_edge(stage: ti.template(), state: ti.template()) -> ti.f64:
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
def _at(model: ti.template(), state: ti.template(), i, rest_shape):
    """Particle i's position now (rest_shape 0) or in the rest shape (1). The distance tests
    run in a loop over the two, so each is compiled once."""
    x = state.particle_position[i]
    if rest_shape:
        x = model.particle_rest_position[i]
    return x


@ti.func
def _triangle_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                    state: ti.template(), t, near, thickness, write):
    """Vertices v whose box over the step meets triangle t's grown by `near`, nearer to t now
    than `near` + how far v moved relative to t's corners in the step, and farther than
    `thickness` from it in the rest shape (counted, or written from pair_start[t] when
    `write`), in cell order."""
    found = 0
    x = ti.static(state.particle_position)
    tri = stage.triangles[t]
    s0, s1, s2 = _start(stage, tri[0]), _start(stage, tri[1]), _start(stage, tri[2])
    now_lo, now_hi = ti.min(x[tri[0]], x[tri[1]], x[tri[2]]), ti.max(x[tri[0]], x[tri[1]], x[tri[2]])
    lo = ti.min(now_lo, s0, s1, s2) - near
    hi = ti.max(now_hi, s0, s1, s2) + near
    first, last = cell_box(stage.grid, lo, hi)
    for k in range(box_cell_count(first, last)):
        cell = box_cell(first, last, k)
        begin, end = cell_range(stage.grid, 0, cell)
        for a in range(begin, end):
            v = stage.grid.cell_item[a]
            if v != tri[0] and v != tri[1] and v != tri[2]:
                if not found_here(stage.grid, v, cell, first, lo, hi):
                    continue
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
                        slot = stage.pair_start[t] + found
                        pairs.elements[slot] = ti.Vector([v, t])
                        pairs.particles[slot] = ti.Vector([v, tri[0], tri[1], tri[2]])
                    found += 1
    return found


@ti.func
def _edge_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                state: ti.template(), e, near, thickness, write):
    """Edges f > e sharing no particle with e whose boxes over the step meet e's grown by
    `near`, nearer to e now than `near` + how far their ends moved relative to each other in
    the step, and farther than `thickness` in the rest shape (counted, or written from
    pair_start[T + e])."""
    found = 0
    x = ti.static(state.particle_position)
    ends = stage.edges[e]
    now_lo, now_hi = ti.min(x[ends[0]], x[ends[1]]), ti.max(x[ends[0]], x[ends[1]])
    lo = stage.grid.lo[stage.particle_count + e] - near
    hi = stage.grid.hi[stage.particle_count + e] + near
    first, last = cell_box(stage.grid, lo, hi)
    for k in range(box_cell_count(first, last)):
        cell = box_cell(first, last, k)
        begin, end = cell_range(stage.grid, 1, cell)
        for a in range(begin, end):
            item = stage.grid.cell_item[a]
            f = item - stage.particle_count
            other = stage.edges[f]
            if f > e and other[0] != ends[0] and other[0] != ends[1] and other[1] != ends[0] \
                    and other[1] != ends[1]:
                if not found_here(stage.grid, item, cell, first, lo, hi):
                    continue
                moved = ti.max(_moved(stage, state, ends[0], other[0]),
                               _moved(stage, state, ends[0], other[1]),
                               _moved(stage, state, ends[1], other[0]),
                               _moved(stage, state, ends[1], other[1]))
                keep = _box_gap(ti.min(x[other[0]], x[other[1]]), ti.max(x[other[0]], x[other[1]]),
                                now_lo, now_hi) < near + moved           # a cheap bound first
                for shape in range(2):                   # now, then the rest shape
                    if keep:
                        d = segment_distance(_at(model, state, ends[0], shape),
                                             _at(model, state, ends[1], shape),
                                             _at(model, state, other[0], shape),
                                             _at(model, state, other[1], shape))
                        keep = ti.select(shape == 0, d < near + moved, d >= thickness)
                if keep:
                    if write:
                        slot = stage.pair_start[stage.triangle_count + e] + found
                        pairs.elements[slot] = ti.Vector([e, f])
                        pairs.particles[slot] = ti.Vector([ends[0], ends[1], other[0],
                                                           other[1]])
                    found += 1
    return found


@ti.kernel
def _list_pairs(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                state: ti.template(), near: float, thickness: float, write: ti.i32):
    """Count (write = 0: pair_start[1 + t] = the pairs of triangle t, pair_start[1 + T + e] =
    of edge e) or, after the prefix sum, write them (write = 1). One kernel for both: it is
    the largest self-collision compiles."""
    for t in range(stage.triangle_count):
        if not write or stage.pair_start[t + 1] > stage.pair_start[t]:
            found = _triangle_pairs(stage, pairs, model, state, t, near, thickness, write)
            if not write:
                stage.pair_start[t + 1] = found
    for e in range(stage.edge_count):
        k = stage.triangle_count + e
        if not write or stage.pair_start[k + 1] > stage.pair_start[k]:
            found = _edge_pairs(stage, pairs, model, state, e, near, thickness, write)
            if not write:
                stage.pair_start[k + 1] = found


@ti.kernel
def _prefix(stage: ti.template()) -> ti.i32:
    """Inclusive prefix sum of the counts (serial): pair_start becomes offsets; the total."""
    stage.pair_start[0] = 0
    for _ in range(1):
        for k in range(stage.triangle_count + stage.edge_count):
            stage.pair_start[k + 1] += stage.pair_start[k]
    return stage.pair_start[stage.triangle_count + stage.edge_count]


@ti.kernel
def _index_contacts(stage: ti.template(), pairs: ti.template()):
    """contact[contact_start[i]:contact_start[i + 1]] = the slots 4 p + k at which pair p
    moves particle i, in pair order (counts, prefix sum and fill all serial)."""
    total = stage.pair_start[stage.triangle_count + stage.edge_count]
    for _ in range(1):
        for i in range(stage.particle_count + 1):
            stage.contact_start[i] = 0
        for p in range(total):
            for k in ti.static(range(4)):
                stage.contact_start[pairs.particles[p][k] + 1] += 1
        for i in range(stage.particle_count):
            stage.contact_start[i + 1] += stage.contact_start[i]
            stage.contact_fill[i] = stage.contact_start[i]
        for p in range(total):
            for k in ti.static(range(4)):
                i = pairs.particles[p][k]
                pairs.contact[stage.contact_fill[i]] = 4 * p + k
                stage.contact_fill[i] += 1


@ti.func
def _vertex_triangle(positions: ti.template(), start: ti.template(), corners, thickness):
    """(in contact, n, gap, w) of vertex corners[0] and triangle corners[1:] at `positions`,
    the side taken from `start`: n the unit normal towards the vertex's side at the start,
    gap = its height over the plane along n minus thickness (< 0 in contact), w the barycentric
    coordinates of its foot."""
    v, a, b, c = corners[0], corners[1], corners[2], corners[3]
    n, h, w = altitude_frame(positions[v], positions[a], positions[b], positions[c])
    inside = w.min() >= -INSIDE and n.norm() > 0
    side = 1.0
    if inside:                                       # else no contact: skip the start's frame
        n0, h0, _ = altitude_frame(start[v], start[a], start[b], start[c])
        side = ti.select(h0 >= 0.0, 1.0, -1.0)
        if n.dot(n0) < 0.0:
            side = -side                             # the triangle turned over in the step
    gap = side * h - thickness
    return inside and gap < 0.0, side * n, gap, w


@ti.func
def _edge_edge(positions: ti.template(), start: ti.template(), corners, thickness):
    """(in contact, n, gap, s, t) of edges corners[0:2] and corners[2:4]: closest points at
    parameters s and t, n the unit direction from the second edge's point to the first's on
    the side they were at the start of the step, gap = distance along n minus thickness."""
    a, b, c, d = corners[0], corners[1], corners[2], corners[3]
    s, t = segment_parameters(positions[a], positions[b], positions[c], positions[d])
    between = (positions[a] + s * (positions[b] - positions[a])
               - positions[c] - t * (positions[d] - positions[c]))
    s0, t0 = segment_parameters(start[a], start[b], start[c], start[d])
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
def _contact_move(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                  state: ti.template(), p, corners, weights, n, gap, friction):
    """Write the position-based projection of contact p with its friction: particle k of
    `corners` moves by -w_k g_k (gap n + f) / sum_j w_j g_j^2 (move[4 p + k])."""
    norm = 0.0
    motion = ti.Vector([0.0, 0.0, 0.0])
    for k in ti.static(range(4)):
        i = corners[k]
        norm += model.particle_inv_mass[i] * weights[k] * weights[k]
        motion += weights[k] * (state.particle_position[i] - stage.step_start[i])
    tangential = motion - motion.dot(n) * n
    length = tangential.norm()
    slip = 0.0
    if length > 0:
        slip = ti.min(friction * -gap / length, 1.0)
    scale = 0.0
    if norm > 0:
        scale = -1.0 / norm
    for k in ti.static(range(4)):
        pairs.move[4 * p + k] = (scale * model.particle_inv_mass[corners[k]] * weights[k]
                                      * (gap * n + slip * tangential))


@ti.kernel
def _evaluate(stage: ti.template(), pairs: ti.template(), model: ti.template(),
              state: ti.template(), thickness: float,
              friction: float) -> ti.types.vector(2, ti.i32):
    """Evaluate every listed pair at the current positions: active[p] and, for contacts,
    their moves. Returns how many are in contact and how many of those deeper than RESOLVED
    thicknesses (integer counts: exact)."""
    stage.touching[None] = ti.Vector([0, 0])
    vertex_pairs = stage.pair_start[stage.triangle_count]
    for p in range(stage.pair_start[stage.triangle_count + stage.edge_count]):
        corners = pairs.particles[p]
        touching = False
        n = ti.Vector([0.0, 0.0, 0.0])
        gap = 0.0
        weights = ti.Vector([0.0, 0.0, 0.0, 0.0])
        if p < vertex_pairs:
            touching, n, gap, w = _vertex_triangle(state.particle_position, stage.step_start,
                                                   corners, thickness)
            weights = ti.Vector([1.0, -w[0], -w[1], -w[2]])
        else:
            touching, n, gap, s, t = _edge_edge(state.particle_position, stage.step_start,
                                                corners, thickness)
            weights = ti.Vector([1.0 - s, s, t - 1.0, -t])
        pairs.active[p] = ti.select(touching, 1, 0)
        if touching:
            _contact_move(stage, pairs, model, state, p, corners, weights, n, gap, friction)
            ti.atomic_add(stage.touching[None][0], 1)
            if gap < -RESOLVED * thickness:
                ti.atomic_add(stage.touching[None][1], 1)
    return stage.touching[None]


@ti.kernel
def _apply_contacts(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                    state: ti.template()):
    """Each particle moves by the mean of its contacts' moves, gathered in pair order."""
    for i in range(stage.particle_count):
        if model.particle_inv_mass[i] > 0:
            move = ti.Vector([0.0, 0.0, 0.0])
            contacts = 0
            for a in range(stage.contact_start[i], stage.contact_start[i + 1]):
                slot = pairs.contact[a]
                if pairs.active[slot // 4]:
                    move += pairs.move[slot]
                    contacts += 1
            if contacts > 0:
                state.particle_position[i] += move / contacts


@ti.kernel
def _follow(stage: ti.template(), state: ti.template(), dt: float):
    """Velocities follow the contact corrections of this stage (v += dx / h)."""
    for i in range(stage.particle_count):
        x = state.particle_position[i]
        state.particle_velocity[i] += (x - stage.before[i]) / dt
