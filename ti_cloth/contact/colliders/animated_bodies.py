"""Animated (deforming) meshes (animated_mesh.py) on the Taichi side: their vertices, triangles
and boxes, placed every step.

Every step, before the particles are resolved (collision.py), four loops place the bodies:
each vertex where the motion has it at the step's start and end (samples interpolated in the
kernel, or a callable's values tabled on the host for the launch's steps), each triangle's
swept box (the box of its six positions, grown by the collider's thickness), and two levels
of boxes over runs of BLOCK triangles and of BLOCK such blocks. The runs follow the triangles
sorted along a Morton curve of their rest centroids, so a run stays a compact patch of
surface however the body moves (a bounding volume hierarchy of fixed shape, refitted each
step, as Bridson et al. 2002 refit theirs for moving cloth).
"""

import numpy as np
import taichi as ti

from ...body.mesh import triangle_edges, unique_rows
from ...inputs import limits
from ...runtime import backend
from ...runtime.plan import ITEM, NOW, Loop, Phase
from ...runtime.transfer import upload
from .candidate_lists import FAR, LISTED, SKIN, CandidateLists

BLOCK = 16          # triangles per block, blocks per group


def morton_order(points: np.ndarray) -> np.ndarray:
    """The order of points (N, 3) along a Morton (Z-order) curve of their bounding box."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    scaled = ((points - lo) / np.maximum(hi - lo, 1e-30) * 1023).astype(np.int64)
    code = np.zeros(len(points), np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((scaled[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def _runs(sizes: list[int]) -> np.ndarray:
    """Starts (len + 1) of consecutive runs of BLOCK items within each of the groups of
    `sizes` items (a run never spans two groups)."""
    starts, first = [0], 0
    for size in sizes:
        starts += [first + k for k in range(BLOCK, size, BLOCK)] + [first + size]
        first += size
    return np.asarray(starts, np.int64)


def tested_edges(collider, triangles: np.ndarray, longest: float) -> np.ndarray:
    """(T, 3) 1 where the cloth's edges meet collider's edge k (corners k, k + 1) of its
    triangles (as ordered here) through this triangle: the first that has the edge, when
    collider.edge_contact tests it (animated_mesh.py: "auto" those whose faces turn by more
    than 2 asin(2 thickness / (1.25 x longest)), longest the cloth's longest rest edge [m]:
    with its particles thickness out of a wedge turning by less, a straight edge up to 1.25 x
    longest cannot reach across its ridge; animated_edges.py)."""
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    ends = triangle_edges(triangles)
    _, first = unique_rows(ends, return_index=True)
    tested = np.zeros(len(ends), np.int32)
    tested[first] = 1
    if collider.edge_contact == "auto":
        edges, turning = collider.edge_turning
        n = collider.mesh.vertex_count
        row = np.searchsorted(edges[:, 0] * n + edges[:, 1], ends[:, 0] * n + ends[:, 1])
        reach = 2.0 * collider.thickness / (1.25 * max(longest, 1e-300))
        least = 2.0 * np.arcsin(min(1.0, reach))
        tested &= turning[row] > least
    elif not collider.edge_contact:
        tested[:] = 0
    return tested.reshape(-1, 3)


@backend.kernel_argument
class AnimatedBodies:
    """The animated mesh colliders of a ColliderSet (`members`: (index in the set, collider)):
    their motion tables, vertices at the step's start and end, triangles and box hierarchy."""

    def __init__(self, members, collider_count: int, particle_count: int):
        self.count = len(members)
        self.particle_count = particle_count
        self.skin = SKIN                               # read at compile time (structure)
        colliders = [c for _, c in members]
        vertex_counts = [c.mesh.vertex_count for c in colliders]
        triangle_counts = [c.mesh.triangle_count for c in colliders]
        self.rows = [len(c.motion) if c.sampled else limits.SCHEDULED_STEPS + 1
                     for c in colliders]
        self.vertex_total = sum(vertex_counts)
        self.triangle_total = sum(triangle_counts)
        blocks = _runs(triangle_counts)
        self.block_total = len(blocks) - 1
        block_counts = [len(_runs([n])) - 1 for n in triangle_counts]
        groups = _runs(block_counts)
        self.group_total = len(groups) - 1
        group_counts = [len(_runs([n])) - 1 for n in block_counts]
        real = backend.real()
        fields = backend.FieldGroup()
        self.frames = fields.vector(3, real, sum(r * v for r, v in zip(self.rows, vertex_counts)))
        self.start = fields.vector(3, real, self.vertex_total)
        self.end = fields.vector(3, real, self.vertex_total)
        self.vertex_body = fields.scalar(ti.i32, self.vertex_total)
        self.triangles = fields.vector(3, ti.i32, self.triangle_total)
        self.triangle_body = fields.scalar(ti.i32, self.triangle_total)
        self.lo = fields.vector(3, real, self.triangle_total + self.block_total + self.group_total)
        self.hi = fields.vector(3, real, self.triangle_total + self.block_total + self.group_total)
        self.block_first = fields.scalar(ti.i32, self.block_total + 1)
        self.group_first = fields.scalar(ti.i32, self.group_total + 1)
        self.body_groups = fields.scalar(ti.i32, self.count + 1)
        self.collider = fields.scalar(ti.i32, self.count)
        self.body_of = fields.scalar(ti.i32, collider_count)
        self.vertex_start = fields.scalar(ti.i32, self.count)
        self.vertex_count = fields.scalar(ti.i32, self.count)
        self.frame_start = fields.scalar(ti.i32, self.count)
        self.row_count = fields.scalar(ti.i32, self.count)
        self.rate = fields.scalar(real, self.count)
        self.stepped = fields.scalar(ti.i32, self.count)
        self.first_step = fields.scalar(ti.i32, self.count)
        self.reference = fields.vector(3, real, self.vertex_total)
        self.reference_epoch = fields.scalar(ti.i32, self.vertex_total)
        self.epoch = fields.scalar(ti.i32, self.count)
        self.drifted = fields.scalar(ti.i32, self.count)
        self.tested = fields.vector(3, ti.i32, self.triangle_total)
        self.edge_contact = fields.scalar(ti.i32, self.count)
        fields.finalize(self)
        self.lists = CandidateLists(max(particle_count, 1) * self.count, 1, LISTED)
        upload(((self.block_first, blocks), (self.group_first, groups),
                (self.body_groups, np.concatenate([[0], np.cumsum(group_counts)]))))

    @staticmethod
    def structure(members) -> tuple:
        """What the kernels read at compile time (collision.ColliderSet.structure, which
        adds the particle count)."""
        return tuple((c.mesh.vertex_count, c.mesh.triangle_count,
                      len(c.motion) if c.sampled else -1) for _, c in members) + (SKIN, LISTED)

    def load(self, members, collider_count: int, longest: float) -> None:
        """Upload the colliders' triangles (in Morton order), the edges the cloth's edges
        meet (tested_edges; `longest` the cloth's longest rest edge [m]) and sampled
        motions."""
        self.members = tuple(members)
        vertex_start, frame_start, triangles, owner, body_of = [], [], [], [], [-1] * collider_count
        tested = []
        offset = frame = 0
        for b, (index, c) in enumerate(self.members):
            rest = c.vertices_at(0.0)
            centroids = rest[c.mesh.triangles].mean(axis=1)
            ordered = c.mesh.triangles[morton_order(centroids)]
            triangles.append(ordered + offset)
            tested.append(tested_edges(c, ordered, longest))
            owner += [b] * c.mesh.vertex_count
            body_of[index] = b
            vertex_start.append(offset)
            frame_start.append(frame)
            offset += c.mesh.vertex_count
            frame += self.rows[b] * c.mesh.vertex_count
        triangles = np.concatenate(triangles)
        tested = np.concatenate(tested)
        per_body = np.split(tested, np.cumsum([c.mesh.triangle_count
                                                for _, c in self.members])[:-1])
        upload(((self.triangles, triangles), (self.tested, tested),
                (self.edge_contact, [int(t.any()) for t in per_body]),
                (self.vertex_body, owner),
                (self.triangle_body, np.asarray(owner)[triangles[:, 0]]),
                (self.collider, [i for i, _ in self.members]), (self.body_of, body_of),
                (self.vertex_start, vertex_start), (self.frame_start, frame_start),
                (self.vertex_count, [c.mesh.vertex_count for _, c in self.members]),
                (self.row_count, self.rows),
                (self.rate, [c.fps if c.sampled else 1.0 for _, c in self.members]),
                (self.stepped, [int(not c.sampled) for _, c in self.members])))
        frames = np.zeros((self.frames.shape[0], 3), backend.numpy_real())
        for b, (_, c) in enumerate(self.members):
            begin = frame_start[b]
            if c.sampled:
                frames[begin:begin + c.motion.size // 3] = c.motion.reshape(-1, 3)
        self.frames.from_numpy(frames)
        self._table = frames                   # the host's copy of the table (schedule)
        self.lists.forget()
        self.reference.fill(FAR)
        self.reference_epoch.fill(0)
        self.epoch.fill(0)
        self.drifted.fill(0)
        self._frame_start = frame_start
        self._cache = {}
        self.schedule(0, 0, None)

    def schedule(self, first: int, count: int, dt: float | None) -> None:
        """Table the callable motions at the step boundaries first .. first + count (times
        k dt): the launch's steps read rows k - first (count <= SCHEDULED_STEPS)."""
        stepped = [(b, c) for b, (_, c) in enumerate(self.members) if not c.sampled]
        if not stepped:
            return
        for b, c in stepped:
            v, begin = c.mesh.vertex_count, self._frame_start[b]
            for row in range(count + 1):
                self._table[begin + row * v: begin + (row + 1) * v] = self._vertices(
                    b, c, (first + row) * dt if dt else 0.0)
        self.frames.from_numpy(self._table)
        self.first_step.from_numpy(np.full(self.count, first, np.int32))

    def _vertices(self, b: int, c, t: float) -> np.ndarray:
        """Body b's vertices at time t (a launch's last boundary is the next one's first)."""
        key = (b, t)
        if key not in self._cache:
            if len(self._cache) > 2 * self.count:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = c.vertices_at(t)
        return self._cache[key]

    def phases(self, colliders) -> tuple:
        """Place every vertex, then every triangle's swept box (and each body's epoch), then
        the blocks', then the groups' (before the particles' loop of the collision stage of
        `colliders`, the ColliderSet these bodies belong to)."""
        return (Phase(Loop(self.vertex_total, place_vertex, colliders, ITEM, NOW)),
                Phase(Loop(self.triangle_total, triangle_box, colliders, ITEM),
                      Loop(self.count, body_drift, colliders, ITEM)),
                Phase(Loop(self.block_total, block_box, colliders, ITEM)),
                Phase(Loop(self.group_total, group_box, colliders, ITEM)))


@ti.func
def _vertex_at(bodies: ti.template(), b, local, boundary, dt):
    """Body b's vertex `local` at the step boundary `boundary` (time boundary x dt): a row of
    the launch's table (callables), or the samples around that time, linearly."""
    base = bodies.frame_start[b]
    rows = bodies.row_count[b]
    v_count = bodies.vertex_count[b]
    position = bodies.frames[base + local]
    if bodies.stepped[b]:
        row = ti.math.clamp(boundary - bodies.first_step[b], 0, rows - 1)
        position = bodies.frames[base + row * v_count + local]
    else:
        s = ti.max(ti.cast(boundary, float) * dt * bodies.rate[b], 0.0)
        row = ti.min(ti.cast(ti.floor(s), ti.i32), rows - 1)
        position = bodies.frames[base + row * v_count + local]
        if row < rows - 1:
            frac = s - ti.cast(row, float)
            following = bodies.frames[base + (row + 1) * v_count + local]
            position = position + frac * (following - position)
    return position


@ti.func
def place_vertex(colliders: ti.template(), v, now: ti.template()):
    """Vertex v where its body's motion has it at the step's start and end."""
    bodies = colliders.bodies
    skin = bodies.skin * colliders.thickness[bodies.collider[bodies.vertex_body[v]]]
    _place_vertex(bodies, v, now.step, now.dt, skin)


@ti.func
def _place_vertex(bodies: ti.template(), v, step, dt, skin):
    """Vertex v at the step's start and end; its reference the start when its body began a
    new epoch since (the end of the step that began it), and the body marked drifted when
    the end is more than `skin` [m] from it (body_drift)."""
    b = bodies.vertex_body[v]
    local = v - bodies.vertex_start[b]
    start = _vertex_at(bodies, b, local, step, dt)
    end = _vertex_at(bodies, b, local, step + 1, dt)
    bodies.start[v] = start
    bodies.end[v] = end
    if bodies.reference_epoch[v] != bodies.epoch[b]:
        bodies.reference[v] = start
        bodies.reference_epoch[v] = bodies.epoch[b]
    if (end - bodies.reference[v]).norm() > skin or skin <= 0.0:
        ti.atomic_max(bodies.drifted[b], 1)          # an integer: the same whatever the order


@ti.func
def triangle_box(colliders: ti.template(), f):
    """Triangle f's box over the step, grown by its collider's thickness."""
    _triangle_box(colliders, colliders.bodies, f)


@ti.func
def _triangle_box(colliders: ti.template(), bodies: ti.template(), f):
    corner = bodies.triangles[f]
    lo = ti.min(bodies.start[corner[0]], bodies.end[corner[0]])
    hi = ti.max(bodies.start[corner[0]], bodies.end[corner[0]])
    for k in ti.static(range(1, 3)):
        lo = ti.min(lo, bodies.start[corner[k]], bodies.end[corner[k]])
        hi = ti.max(hi, bodies.start[corner[k]], bodies.end[corner[k]])
    grow = colliders.thickness[bodies.collider[bodies.triangle_body[f]]]
    bodies.lo[f] = lo - grow
    bodies.hi[f] = hi + grow


@ti.func
def _union(bodies: ti.template(), target, first, end):
    lo, hi = bodies.lo[first], bodies.hi[first]
    for k in range(first + 1, end):
        lo, hi = ti.min(lo, bodies.lo[k]), ti.max(hi, bodies.hi[k])
    bodies.lo[target] = lo
    bodies.hi[target] = hi


@ti.func
def block_box(colliders: ti.template(), k):
    """Block k's box: the union of its triangles'."""
    bodies = colliders.bodies
    _union(bodies, bodies.triangle_total + k, bodies.block_first[k], bodies.block_first[k + 1])


@ti.func
def group_box(colliders: ti.template(), g):
    """Group g's box: the union of its blocks'."""
    bodies = colliders.bodies
    offset = bodies.triangle_total
    _union(bodies, offset + bodies.block_total + g, offset + bodies.group_first[g],
           offset + bodies.group_first[g + 1])


@ti.func
def body_drift(colliders: ti.template(), b):
    """Body b's vertices against where they were when its candidate lists were made: once
    one has moved more than SKIN x thickness (place_vertex marks it), every list of it is
    stale (a new epoch), and the positions now become the new reference (each vertex takes
    its own at the next step's start: the same positions)."""
    bodies = colliders.bodies
    if bodies.drifted[b]:
        bodies.epoch[b] += 1
        bodies.drifted[b] = 0
