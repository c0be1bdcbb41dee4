"""Contact with animated (deforming) meshes (animated_mesh.py): the Taichi side.

Every step, before the particles are resolved (collision.py), four loops place the bodies:
each vertex where the motion has it at the step's start and end (samples interpolated in the
kernel, or a callable's values tabled on the host for the launch's steps), each triangle's
swept box (the box of its six positions, grown by the collider's thickness), and two levels
of boxes over runs of BLOCK triangles and of BLOCK such blocks. The runs follow the triangles
sorted along a Morton curve of their rest centroids, so a run stays a compact patch of
surface however the body moves (a bounding volume hierarchy of fixed shape, refitted each
step, as Bridson et al. 2002 refit theirs for moving cloth).

A particle that moved from x0 to x in the step meets the triangles whose boxes meet the box of
its path, each in two ways:
- continuous: the first time t in (0, 1] at which the particle, moving linearly, lies in the
  plane of the triangle, moving linearly (the roots of a cubic, Provot 1997 / Bridson et al.
  2002 eq. 1), with its point at that time inside the triangle: it passed through;
- proximity: at the step's end its foot is inside the triangle and its height on the side it
  started on is below the thickness (and above minus the thickness: deeper is a crossing,
  which the first test finds); or, on that side with its foot outside, its distance to the
  nearest point of the triangle's edges is below the thickness (the wedge over a convex edge
  or corner, which no triangle's foot covers), pushed away from that point.
The worst contact (the earliest crossing, else the deepest) is answered as every collider's
(colliders.py: out to the thickness along the triangle's normal on the particle's side, Coulomb
friction against the surface point's own motion over the step), then the particle's new path
is tested again, up to PASSES times (after the first answer, contacts shallower than RESOLVED
thicknesses - rounding - are left). A path that enters and leaves a triangle within one step
ends on the side it started, so only a path whose end is across a triangle's plane is solved
for its crossing. Each answer is a function of the set of contacts found,
visited in a fixed order: reruns and thread counts give the same bits.

Candidate lists (a Verlet list per particle and body, as molecular dynamics keeps): a
particle's traversal also writes down, in index order, the triangles whose boxes meet its
path's box grown by 3 x SKIN x thickness, and it tests only those while it stays within SKIN x
thickness of where it was then and the body's vertices stay within SKIN x thickness of the
reference they were at (place_vertex, body_drift: beyond it, a new epoch makes every list
stale). Any
triangle whose box meets a later path's box was then within reach (the particle moved at most
one skin, each triangle corner at most two), so the list holds every triangle a traversal
would visit, in the same order: the answers are the same bits as a traversal every step.
More than LISTED candidates, and the particle traverses until its next list.
"""


import numpy as np
import taichi as ti

from ...body.mesh import triangle_edges, unique_rows
from ...geometry import foot_barycentric, nearest_on_edges
from ...inputs import limits
from ...runtime import backend
from ...runtime.plan import Loop, Phase
from ...runtime.transfer import upload

BLOCK = 16          # triangles per block, blocks per group
PASSES = 4          # contacts answered per particle and body in a step, at most
RESOLVED = 1e-4     # after the first, contacts shallower than this (in thicknesses) are left
INSIDE = 1e-4       # a point this far outside a triangle (barycentric) still meets it
BISECTIONS = 40     # halvings of a crossing's time interval
SKIN = 0.5          # candidate lists hold while particle and body move less than this x thickness
LISTED = 32         # candidates a particle keeps per body (more: it traverses every time)
FAR = 1e30          # an anchor no particle is near: its list is made on first use


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
class CandidateLists:
    """Candidate lists (module doc) in `slots` slots, one per element (a particle or an edge)
    and body: up to `size` triangles each (listed[slot * size + k]; count -1: it overflowed),
    the `anchors` positions of the element's particles when it was made (anchor[slot *
    anchors + k]) and the body's epoch then."""

    def __init__(self, slots: int, anchors: int, size: int):
        self.size, self.anchors = size, anchors        # read at compile time (structure)
        fields = backend.FieldGroup()
        self.listed = fields.scalar(ti.i32, slots * self.size)
        self.count = fields.scalar(ti.i32, slots)
        self.anchor = fields.vector(3, backend.real(), slots * anchors)
        self.epoch = fields.scalar(ti.i32, slots)
        fields.finalize(self)

    def forget(self) -> None:
        """Every list made again on first use."""
        self.anchor.fill(FAR)
        self.epoch.fill(-1)


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

    def phases(self) -> tuple:
        """Place every vertex, then every triangle's swept box (and each body's epoch), then
        the blocks', then the groups' (before the particles' loop of the collision stage)."""
        return (Phase(Loop(self.vertex_total, place_vertex)),
                Phase(Loop(self.triangle_total, triangle_box), Loop(self.count, body_drift)),
                Phase(Loop(self.block_total, block_box)),
                Phase(Loop(self.group_total, group_box)))


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
def place_vertex(model: ti.template(), state: ti.template(), forces: ti.template(),
                 colliders: ti.template(), stages: ti.template(), v, now: ti.template()):
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
def triangle_box(model: ti.template(), state: ti.template(), forces: ti.template(),
                 colliders: ti.template(), stages: ti.template(), f, now: ti.template()):
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
def block_box(model: ti.template(), state: ti.template(), forces: ti.template(),
              colliders: ti.template(), stages: ti.template(), k, now: ti.template()):
    """Block k's box: the union of its triangles'."""
    bodies = colliders.bodies
    _union(bodies, bodies.triangle_total + k, bodies.block_first[k], bodies.block_first[k + 1])


@ti.func
def group_box(model: ti.template(), state: ti.template(), forces: ti.template(),
              colliders: ti.template(), stages: ti.template(), g, now: ti.template()):
    """Group g's box: the union of its blocks'."""
    bodies = colliders.bodies
    offset = bodies.triangle_total
    _union(bodies, offset + bodies.block_total + g, offset + bodies.group_first[g],
           offset + bodies.group_first[g + 1])


@ti.func
def body_drift(model: ti.template(), state: ti.template(), forces: ti.template(),
               colliders: ti.template(), stages: ti.template(), b, now: ti.template()):
    """Body b's vertices against where they were when its candidate lists were made: once
    one has moved more than SKIN x thickness (place_vertex marks it), every list of it is
    stale (a new epoch), and the positions now become the new reference (each vertex takes
    its own at the next step's start: the same positions)."""
    bodies = colliders.bodies
    if bodies.drifted[b]:
        bodies.epoch[b] += 1
        bodies.drifted[b] = 0


@ti.func
def _meets(bodies: ti.template(), k, lo, hi):
    return (bodies.lo[k] <= hi).all() and (lo <= bodies.hi[k]).all()


@ti.func
def _cubic(c0, c1, c2, c3, t):
    return ((c3 * t + c2) * t + c1) * t + c0


@ti.func
def _crossing(x0, x1, a0, a1, b0, b1, c0, c1):
    """The first time t in (0, 1] at which x lies in the plane of abc and inside the
    triangle, all moving linearly from their step-start (0) to step-end (1) positions; 2 if
    none. The coplanarity (b - a) x (c - a) . (x - a) = 0 is a cubic in t (Provot 1997); its
    monotone pieces between the roots of its derivative are bisected."""
    e1, e2, q = b0 - a0, c0 - a0, x0 - a0
    d1, d2, dq = (b1 - a1) - e1, (c1 - a1) - e2, (x1 - a1) - q
    n0 = e1.cross(e2)
    n1 = e1.cross(d2) + d1.cross(e2)
    n2 = d1.cross(d2)
    k0 = n0.dot(q)
    k1 = n0.dot(dq) + n1.dot(q)
    k2 = n1.dot(dq) + n2.dot(q)
    k3 = n2.dot(dq)
    # the pieces' ends: 0, the derivative's roots in (0, 1) in order, 1
    ends = ti.Vector([0.0, 1.0, 1.0, 1.0])
    qa, qb, qc = 3.0 * k3, 2.0 * k2, k1
    if qa != 0.0:
        disc = qb * qb - 4.0 * qa * qc
        if disc > 0.0:
            root = ti.sqrt(disc)
            r1 = (-qb - root) / (2.0 * qa)
            r2 = (-qb + root) / (2.0 * qa)
            ends[1], ends[2] = ti.min(r1, r2), ti.max(r1, r2)
    elif qb != 0.0:
        ends[1] = -qc / qb
    for k in ti.static(range(1, 3)):
        ends[k] = ti.math.clamp(ends[k], 0.0, 1.0)
    found = 2.0
    for piece in range(3):
        lo, hi = ends[piece], ends[piece + 1]
        if found > 1.0 and hi > lo:
            f_lo = _cubic(k0, k1, k2, k3, lo)
            f_hi = _cubic(k0, k1, k2, k3, hi)
            if (f_lo > 0.0 and f_hi <= 0.0) or (f_lo < 0.0 and f_hi >= 0.0):
                for _ in range(BISECTIONS):
                    mid = 0.5 * (lo + hi)
                    f_mid = _cubic(k0, k1, k2, k3, mid)
                    if (f_mid > 0.0) == (f_lo > 0.0) and f_mid != 0.0:
                        lo, f_lo = mid, f_mid
                    else:
                        hi = mid
                t = hi
                w, _ = foot_barycentric(x0 + t * (x1 - x0), a0 + t * (a1 - a0), b0 + t * (b1 - b0),
                                    c0 + t * (c1 - c0))
                if w.min() >= -INSIDE:
                    found = t
    return found


@ti.func
def _against(x0, x, a0, b0, c0, a1, b1, c1, thickness):
    """The path x0 -> x against one triangle moving from a0 b0 c0 to a1 b1 c1 (module doc):
    (t, depth, n, w): t the crossing's time (2: none), depth how far x is inside the
    thickness along n (0: no contact), n the unit direction out on the particle's side, w
    the barycentric coordinates of the surface point it touches at the end. Cheap tests
    first: the heights over the planes at the start and end say whether the path can cross
    (their signs differ) or come near (the end height below the thickness); only then the
    cubic, the foot or the edges."""
    m0 = (b0 - a0).cross(c0 - a0)
    m1 = (b1 - a1).cross(c1 - a1)
    area1 = m1.dot(m1)
    t, depth = 2.0, 0.0
    n = ti.Vector([0.0, 1.0, 0.0])
    w = ti.Vector([1.0, 0.0, 0.0])
    if area1 > 0 and m0.dot(m0) > 0:
        side = ti.select(m0.dot(x0 - a0) >= 0.0, 1.0, -1.0)
        if m0.dot(m1) < 0.0:
            side = -side                       # the triangle turned over in the step
        above = side * m1.dot(x - a1)          # the end height on the start side, x |m1|
        if above < 0.0:                        # across the plane: through the triangle?
            t = _crossing(x0, x, a0, a1, b0, b1, c0, c1)
        reach = thickness * thickness * area1
        if t <= 1.0 or above * above < reach:
            length = ti.sqrt(area1)
            n = side * m1 / length
            gap = above / length
            w, _ = foot_barycentric(x, a1, b1, c1)
            if t <= 1.0 or w.min() >= -INSIDE:
                depth = thickness - gap
            elif gap > 0.0:                    # beside it: nearest one of its edges
                q, w = nearest_on_edges(x, a1, b1, c1)
                distance = (x - q).norm()
                if distance > 0.0 and distance < thickness:
                    n = (x - q) / distance
                    depth = thickness - distance
    return t, depth, n, w


@ti.func
def stale_list(bodies: ti.template(), lists: ti.template(), slot, b, k, x0, x, skin):
    """Whether list `slot` (of body b) no longer holds for its particle k moving x0 -> x: made
    in another epoch, or the particle is farther than the skin from its anchor."""
    anchor = lists.anchor[slot * lists.anchors + k]
    return (lists.epoch[slot] != bodies.epoch[b] or (x0 - anchor).norm() > skin
            or (x - anchor).norm() > skin)


@ti.func
def _wanted(bodies: ti.template(), f, edges: ti.template()):
    """Whether triangle f is visited: always, or (edges) when it has an edge to test."""
    wanted = True
    if ti.static(edges):
        wanted = (bodies.tested[f] != 0).any()
    return wanted


@ti.func
def visit_near(bodies: ti.template(), lists: ti.template(), slot, b, lo, hi, stale, skin,
               visit: ti.template(), query, found, edges: ti.template()):
    """found = visit(bodies, f, query, found) for every triangle f of body b whose box meets
    the box [lo, hi] (with `edges`, of those with an edge to test), in the hierarchy's order:
    from list `slot` while it holds, else by traversing the hierarchy, and when it is stale
    making it anew (the triangles within three skins of the box; the caller sets its
    anchors).

    One loop yields the candidates of either source, the traversal walking groups, blocks
    and triangles as a cursor, so `visit` (the contact test, most of the code) is compiled
    once: two call sites, one per source, took a third more of the build of a step with an
    animated collider (docs/performance.md)."""
    traverse = stale or lists.count[slot] < 0
    reach = ti.select(stale, 3.0 * skin, 0.0)
    count = 0
    blocks = bodies.triangle_total
    groups = blocks + bodies.block_total
    g, g_end = bodies.body_groups[b], bodies.body_groups[b + 1]
    k, k_end, f, f_end, n = 0, 0, 0, 0, 0
    more = True
    while more:
        candidate = -1
        if not traverse:
            if n < lists.count[slot]:
                candidate = lists.listed[slot * lists.size + n]
                n += 1
            else:
                more = False
        elif f < f_end:                        # the next triangle of the current block
            if _wanted(bodies, f, edges):
                candidate = f
            f += 1
        elif k < k_end:                        # the next block of the current group
            if _meets(bodies, blocks + k, lo - reach, hi + reach):
                f, f_end = bodies.block_first[k], bodies.block_first[k + 1]
            k += 1
        elif g < g_end:                        # the next group of the body
            if _meets(bodies, groups + g, lo - reach, hi + reach):
                k, k_end = bodies.group_first[g], bodies.group_first[g + 1]
            g += 1
        else:
            more = False
        if traverse and stale and candidate >= 0 and _meets(bodies, candidate, lo - reach,
                                                            hi + reach):
            if count >= 0 and count < lists.size:
                lists.listed[slot * lists.size + count] = candidate
                count += 1
            else:
                count = -1
        if candidate >= 0 and _meets(bodies, candidate, lo, hi):
            found = visit(bodies, candidate, query, found)
    if stale:
        lists.count[slot] = count
        lists.epoch[slot] = bodies.epoch[b]
    return found


@ti.func
def worst_contact(colliders: ti.template(), c, i, x0, x, thickness, least):
    """The worst contact of particle i's path x0 -> x with animated collider c's triangles
    (module doc), of those deeper than `least` [m] if none crosses: (found, unit normal on the
    particle's side at the step's end, depth to the thickness [m], the surface point's
    displacement over the step [m])."""
    bodies = colliders.bodies
    lists = bodies.lists
    b = bodies.body_of[c]
    slot = i * bodies.count + b
    skin = bodies.skin * thickness
    stale = stale_list(bodies, lists, slot, b, 0, x0, x, skin)
    query = ti.Vector([x0[0], x0[1], x0[2], x[0], x[1], x[2], thickness])
    # found, normal (3), depth, moved (3), the earliest crossing, the deepest contact
    found = ti.Vector([0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, least])
    found = visit_near(bodies, lists, slot, b, ti.min(x0, x), ti.max(x0, x), stale, skin,
                       _consider, query, found, False)
    if stale:
        lists.anchor[slot] = x
    return (found[0] > 0.0, ti.Vector([found[1], found[2], found[3]]), found[4],
            ti.Vector([found[5], found[6], found[7]]))


@ti.func
def _consider(bodies: ti.template(), f, query, found):
    """Triangle f against the path query[0:3] -> query[3:6] (thickness query[6]): the
    contact so far (worst_contact's `found`) replaced when f's crossing is earlier, or (no
    crossing yet) its contact deeper."""
    x0 = ti.Vector([query[0], query[1], query[2]])
    x = ti.Vector([query[3], query[4], query[5]])
    corner = bodies.triangles[f]
    a0, b0, c0 = bodies.start[corner[0]], bodies.start[corner[1]], bodies.start[corner[2]]
    a1, b1, c1 = bodies.end[corner[0]], bodies.end[corner[1]], bodies.end[corner[2]]
    t, d, n, w = _against(x0, x, a0, b0, c0, a1, b1, c1, query[6])
    if t < found[8] or (found[8] > 1.0 and d > found[9]):
        if t <= 1.0:
            found[8] = t
        else:
            found[9] = d
        w = ti.math.clamp(w, 0.0, 1.0)
        w = w / w.sum()
        moved = w[0] * (a1 - a0) + w[1] * (b1 - b0) + w[2] * (c1 - c0)
        found[0] = 1.0
        for k in ti.static(range(3)):
            found[1 + k] = n[k]
            found[5 + k] = moved[k]
        found[4] = d
    return found
