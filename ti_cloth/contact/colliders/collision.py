"""The collision stage: a simulation's colliders (colliders.py, mesh_collider.py,
animated_mesh.py) as Taichi fields, and the kernels that keep particles out of them with the
response colliders.py describes. A set without mesh colliders compiles none of the mesh code,
one without turning meshes none of the turning code, one without animated meshes none of
theirs (animated_contact.py)."""

import numpy as np
import taichi as ti

from ...inputs import limits
from ...inputs.validation import require
from ...runtime import backend, plan
from ...runtime.plan import ITEM, NOW, STATE, Loop, Phase, Repeat
from ...runtime.transfer import upload
from ...state import copy_positions
from ..broad_phase.contact_pairs import cloth_edges
from .animated_bodies import AnimatedBodies, tested_edges
from .animated_contact import PASSES, RESOLVED, worst_contact
from .animated_edges import EDGE_PASSES, EdgeContacts, edge_against_bodies, follow_edges
from .animated_mesh import AnimatedMeshCollider
from .mesh_collider import MeshCollider
from .sdf import layout, mesh_distance, sample_grid
from .shapes import ANIMATED, MESH, Collider, Plane, signed_distance

PLACEMENT = 30       # numbers per collider in a placement row (ColliderSet._placement)


@backend.kernel_argument
class ColliderSet:
    """The colliders of one simulation as Taichi fields (one row per collider), and the
    particle positions at the start of the current step (`step_start`) the response needs, and
    which particles the step's response pushed out of a collider (`touched`: rests_on).
    Mesh colliders add their distance grids, one after another in `samples`, and their pose:
    `a` the mesh centre's position and `rotation` (a 3x3 matrix, row-major) now, `a_prev` and
    `rotation_prev` at the start of the step. Animated meshes are in `bodies` (an
    AnimatedBodies), placed by the stage's first phases every step."""

    def __init__(self, colliders, cloth):
        real, count = backend.real(), len(colliders)
        particle_count = cloth.particle_count
        self.nodes, self.meshes, self.turning, self.shells = self.structure(colliders,
                                                                            cloth)[3:7]
        members = _animated(colliders)
        self.animated = bool(members)
        self.edge_contact = _edge_contact(colliders, cloth)
        if self.animated:
            self.bodies = AnimatedBodies(members, count, particle_count)
        if self.edge_contact:
            self.edges = EdgeContacts(cloth, len(members))
        self.count = count
        fields = backend.FieldGroup()
        self.kind = fields.scalar(ti.i32, count)
        self.a = fields.vector(3, real, count)
        self.b = fields.vector(3, real, count)
        self.radius = fields.scalar(real, count)
        self.thickness = fields.scalar(real, count)
        self.static_friction = fields.scalar(real, count)
        self.kinetic_friction = fields.scalar(real, count)
        self.velocity = fields.vector(3, real, count)
        self.step_start = fields.vector(3, real, particle_count)
        self.touched = fields.scalar(ti.i32, particle_count)    # 1: pushed out this step
        self.scheduled = fields.vector(PLACEMENT, real, limits.SCHEDULED_STEPS * count)
        if self.meshes:
            self.samples = fields.vector(4, real, self.nodes)
            self.grid_start = fields.scalar(ti.i32, count)
            self.grid_shape = fields.vector(3, ti.i32, count)
            self.grid_origin = fields.vector(3, real, count)
            self.grid_cell = fields.scalar(real, count)
            self.shell = fields.scalar(ti.i32, count)
            self.centre = fields.vector(3, real, count)
            self.a_prev = fields.vector(3, real, count)
            self.rotation = fields.vector(9, real, count)
            self.rotation_prev = fields.vector(9, real, count)
        fields.finalize(self)
        self.load(colliders, cloth)

    @staticmethod
    def structure(colliders, cloth) -> tuple:
        """What the kernels of a ColliderSet read at compile time: sets of equal structure
        are interchangeable once load() has put the colliders in (pool.py). (count, particle
        count, grid nodes of all meshes, whether any is a mesh, whether any mesh turns,
        whether any mesh is a shell)."""
        meshes = [c for c in colliders if isinstance(c, MeshCollider)]
        nodes = sum(int(np.prod(layout(c.mesh.vertices, c.resolution, c.margin)[2]))
                    for c in meshes)
        return ("ColliderSet", len(colliders), cloth.particle_count, nodes, bool(meshes),
                any(c.rotation is not None for c in meshes), any(not c.solid for c in meshes),
                AnimatedBodies.structure(_animated(colliders)),
                EdgeContacts.structure(cloth, len(_animated(colliders)))
                if _edge_contact(colliders, cloth) else None)

    def load(self, colliders, cloth) -> None:
        """Upload `colliders` (as many as this set holds), placed at time 0."""
        self.colliders = tuple(colliders)
        for c in self.colliders:
            require(isinstance(c, Collider) and type(c) is not Collider, "colliders", c,
                    "Plane, Sphere, Box, Capsule, MeshCollider or AnimatedMeshCollider objects")
        packed = [c.packed() for c in self.colliders]
        self.moving = self.animated or any(c.path is not None
                                           or getattr(c, "rotation", None) is not None
                                           for c in self.colliders)
        if self.animated:
            self.bodies.load(_animated(self.colliders), self.count, _longest_edge(cloth))
        if self.edge_contact:
            self.edges.load(cloth, len(_animated(self.colliders)))
        self._rest = [(p[1], p[2]) for p in packed]
        upload(((self.kind, [p[0] for p in packed]), (self.radius, [p[3] for p in packed]),
                (self.thickness, [c.thickness for c in self.colliders]),
                (self.static_friction, [c.static_friction for c in self.colliders]),
                (self.kinetic_friction, [c.kinetic_friction for c in self.colliders]))
               + self._grids())
        self._turns = {}
        self.place(0.0)

    def place(self, t: float, dt: float | None = None) -> None:
        """Put every collider where its path (and rotation) says at time t; velocity and the
        previous pose from t - dt (the same as now when dt is None: at the start)."""
        write_placement(self, self._placement(t, dt))

    def schedule(self, first: int, count: int, dt: float) -> None:
        """Write the placements at the ends of steps first .. first + count - 1 (count at
        most limits.SCHEDULED_STEPS) for a many-steps launch (place_scheduled)."""
        rows = np.stack([self._placement((first + k + 1) * dt, dt) for k in range(count)])
        if self.animated:
            self.bodies.schedule(first, count, dt)
        table = np.zeros((limits.SCHEDULED_STEPS * self.count, PLACEMENT), backend.numpy_real())
        table[:count * self.count] = rows.reshape(-1, PLACEMENT)
        self.scheduled.from_numpy(table)

    @ti.func
    def place_scheduled(self, k):
        """Put the colliders where schedule() said for the k-th step of the launch."""
        for c in range(self.count):
            place_collider(self, c, self.scheduled[k * self.count + c])

    def before_step(self, state, t: float) -> None:
        """Keep the positions at the step start: the friction response needs the step's motion."""
        copy_positions(state, self.step_start)

    def phases(self, model, forces, work) -> tuple:
        """The collision stage as phases (runtime/plan.py; `work` is this set): the animated
        meshes placed, then every particle out of the colliders where they are placed
        (resolve), from its position at the step's start (step_start), then the cloth's
        edges out of the animated meshes' edges in EDGE_PASSES passes (animated_edges.py),
        then the particles they moved out of the colliders again (resolve_shifted)."""
        placing = self.bodies.phases(self) if self.animated else ()
        edges = ((Repeat(EDGE_PASSES,
                         Phase(Loop(self.edges.count, edge_against_bodies, model, STATE, work,
                                    ITEM, NOW)),
                         Phase(Loop(model.particle_count, follow_edges, model, STATE, work, ITEM,
                                    NOW))),
                  Phase(Loop(model.particle_count, resolve_shifted, model, STATE, work, ITEM,
                             NOW)))
                 if self.edge_contact else ())
        return (placing + (Phase(Loop(model.particle_count, resolve, model, STATE, work, ITEM,
                                      NOW)),)
                + edges)

    @property
    def launched(self):
        """The object a many-steps launch runs this stage's phases on: itself (stages.py)."""
        return self

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The collision stage of a step ending at time t (stages.STEP_ORDER): the
        colliders placed, then a launch of its phases."""
        if self.moving:
            self.place(t, dt)
        if self.animated:
            self.bodies.schedule(step_index, 1, dt)
        plan.run(self, model, state, None, self, dt, step_index, False)

    def distance(self, points, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(distance [m] of each point from each collider's surface, negative inside, shape
        (N, count); outward normal, shape (N, count, 3)) where the colliders are now (the
        animated meshes at time t [s]). A shell reports the unsigned distance, an animated
        mesh the exact one (sdf.mesh_distance)."""
        real = backend.numpy_real()
        points = np.ascontiguousarray(points, dtype=real).reshape(-1, 3)
        distance = np.zeros((len(points), self.count), real)
        normal = np.zeros((len(points), self.count, 3), real)
        if len(points):
            measure_distances(self, points, distance, normal)
        distance, normal = distance.astype(np.float64), normal.astype(np.float64)
        for c, collider in _animated(self.colliders):
            distance[:, c], normal[:, c] = mesh_distance(collider.vertices_at(t),
                                                         collider.mesh.triangles,
                                                         points.astype(np.float64),
                                                         collider.closed)
        return distance, normal

    def _grids(self) -> tuple:
        """(field, values) of the mesh colliders' grids; their samples are copied in here."""
        if not self.meshes:
            return ()
        start, shape, origin, cell, shell, centre, samples = [], [], [], [], [], [], []
        for c in self.colliders:
            grid = c.grid() if isinstance(c, MeshCollider) else None
            start.append(sum(len(s) for s in samples))
            shape.append(grid.shape if grid else (2, 2, 2))
            origin.append(grid.origin if grid else np.zeros(3))
            cell.append(grid.cell if grid else 1.0)
            shell.append(int(grid is not None and not c.solid))
            centre.append(c.centre if grid else np.zeros(3))
            if grid:
                samples.append(grid.samples(c.solid))
        self.samples.from_numpy(np.concatenate(samples).astype(backend.numpy_real()))
        return ((self.grid_start, start), (self.grid_shape, shape), (self.grid_origin, origin),
                (self.grid_cell, cell), (self.shell, shell), (self.centre, centre))

    def _placement(self, t: float, dt: float | None) -> np.ndarray:
        """Per collider (rows): a, b, velocity, and for meshes a_prev, rotation and
        rotation_prev (row-major), at time t and t - dt (place(); write_placement's layout)."""
        rows = np.zeros((self.count, PLACEMENT), backend.numpy_real())
        for c, (collider, (a0, b0)) in enumerate(zip(self.colliders, self._rest)):
            offset = collider.offset(t)
            moving = collider.path is not None and dt is not None
            before = collider.offset(t - dt) if moving else offset
            rows[c, 0:3] = a0 + offset
            rows[c, 3:6] = b0 if isinstance(collider, Plane) else b0 + offset   # a plane's normal
            rows[c, 6:9] = (offset - before) / dt if moving else 0.0
            rows[c, 9:12] = a0 + before
            turning = isinstance(collider, MeshCollider) and collider.rotation is not None
            now = self._turn(c, t) if turning else np.eye(3)
            rows[c, 12:21] = now.ravel()
            rows[c, 21:30] = (self._turn(c, t - dt) if turning and dt is not None else now).ravel()
        return rows

    def _turn(self, c: int, t: float) -> np.ndarray:
        """Collider c's rotation at time t; the last few are remembered (a step's end is the
        next step's start)."""
        turns = self._turns.setdefault(c, {})
        if t not in turns:
            turns[t] = self.colliders[c].turn(t)
            if len(turns) > 3:
                turns.pop(next(iter(turns)))
        return turns[t]




def _animated(colliders) -> list:
    """(index, collider) of the animated mesh colliders among `colliders`."""
    return [(i, c) for i, c in enumerate(colliders) if isinstance(c, AnimatedMeshCollider)]


def _longest_edge(cloth) -> float:
    """The cloth's longest rest edge of a triangle [m] (0 without triangles)."""
    edges = cloth_edges(cloth)[0]
    rest = cloth.particle_position
    return float(np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1).max(initial=0.0))


def _edge_contact(colliders, cloth) -> bool:
    """Whether the cloth has edges and an animated mesh among `colliders` has edges they
    meet (animated_bodies.tested_edges)."""
    if cloth.mesh.triangle_count == 0:
        return False
    longest = _longest_edge(cloth)
    return any(tested_edges(c, c.mesh.triangles, longest).any() for _, c in _animated(colliders))


@ti.func
def place_collider(colliders: ti.template(), c, row):
    """Collider c's pose from a placement row (ColliderSet._placement's layout)."""
    for k in ti.static(range(3)):
        colliders.a[c][k] = row[k]
        colliders.b[c][k] = row[3 + k]
        colliders.velocity[c][k] = row[6 + k]
    if ti.static(colliders.meshes):
        for k in ti.static(range(3)):
            colliders.a_prev[c][k] = row[9 + k]
        for k in ti.static(range(9)):
            colliders.rotation[c][k] = row[12 + k]
            colliders.rotation_prev[c][k] = row[21 + k]


@backend.kernel
def write_placement(colliders: ti.template(), rows: ti.types.ndarray()):
    """Copy ColliderSet._placement's rows into the colliders' fields (one launch per step)."""
    for c in range(colliders.count):
        row = ti.Vector([rows[c, k] for k in ti.static(range(PLACEMENT))])
        place_collider(colliders, c, row)


@ti.func
def _matrix(rows):
    """A 3x3 matrix from its 9 entries, row-major."""
    return ti.Matrix([[rows[0], rows[1], rows[2]], [rows[3], rows[4], rows[5]],
                      [rows[6], rows[7], rows[8]]])


@ti.func
def _mesh_distance(colliders: ti.template(), c, x, x0):
    """Mesh collider c's (distance, normal) at x: the grid sampled at x in the mesh's rest
    frame. A shell's sign says the side: negative when x is across the surface from where
    the particle was at the step's start x0 (in the pose of that time)."""
    turn = _matrix(colliders.rotation[c])
    q = turn.transpose() @ (x - colliders.a[c]) + colliders.centre[c]
    start, shape = colliders.grid_start[c], colliders.grid_shape[c]
    origin, cell = colliders.grid_origin[c], colliders.grid_cell[c]
    d, g = sample_grid(colliders.samples, start, shape, origin, cell, q)
    if ti.static(colliders.shells):
        if colliders.shell[c]:
            q0 = (_matrix(colliders.rotation_prev[c]).transpose() @ (x0 - colliders.a_prev[c])
                  + colliders.centre[c])
            _, g0 = sample_grid(colliders.samples, start, shape, origin, cell, q0)
            if g.dot(g0) < 0:
                d, g = -d, -g
    n = turn @ g
    length = n.norm()
    if length > 0:
        n /= length
    else:
        n = ti.Vector([0.0, 1.0, 0.0])
    return d, n


@ti.func
def collider_distance(colliders: ti.template(), c, x, x0):
    """Distance [m] from x to collider c's surface (negative inside or, for a shell, across
    from x0, the particle's position at the step's start) and the outward normal."""
    d, n = 0.0, ti.Vector([0.0, 1.0, 0.0])
    if ti.static(colliders.meshes):
        if colliders.kind[c] == MESH:
            d, n = _mesh_distance(colliders, c, x, x0)
        else:
            d, n = signed_distance(colliders.kind[c], colliders.a[c], colliders.b[c],
                                   colliders.radius[c], x)
    else:
        d, n = signed_distance(colliders.kind[c], colliders.a[c], colliders.b[c],
                               colliders.radius[c], x)
    return d, n


@ti.func
def surface_velocity(colliders: ti.template(), c, x, dt):
    """Velocity [m/s] of collider c's surface at x over the step: the path's, and for a
    turning mesh the motion of the surface point now at x since the step's start."""
    v = colliders.velocity[c]
    if ti.static(colliders.turning):
        if colliders.kind[c] == MESH:
            local = _matrix(colliders.rotation[c]).transpose() @ (x - colliders.a[c])
            before = _matrix(colliders.rotation_prev[c]) @ local + colliders.a_prev[c]
            v = (x - before) / dt
    return v


@ti.func
def _friction(colliders: ti.template(), c, x, x0, n, depth, vc, dt):
    """(position, velocity) of a particle just pushed out by `depth` along n to x, which was
    at x0 at the step's start: Coulomb friction on its displacement relative to the surface
    (moving at vc), then its velocity without approach (colliders.py)."""
    slide = x - x0 - vc * dt
    tangential = slide - slide.dot(n) * n
    length = tangential.norm()
    if length <= colliders.static_friction[c] * depth:
        x -= tangential
    else:
        x -= tangential * ti.min(colliders.kinetic_friction[c] * depth / length, 1.0)
    v = (x - x0) / dt
    approach = (v - vc).dot(n)
    if approach < 0:
        v -= approach * n
    return x, v


@ti.func
def _collide_with(colliders: ti.template(), c, i, x0, x, v, dt, with_friction: ti.template()):
    """Particle i at x, which was at x0 at the step's start, out of collider c: (position,
    velocity, touched). with_friction: the full response (colliders.py; an animated mesh
    answers up to PASSES contacts: animated_contact.py); else the push-out alone, v kept."""
    touched = False
    animated = False
    if ti.static(colliders.animated):
        animated = colliders.kind[c] == ANIMATED
        if animated:
            least = 0.0
            for _ in range(PASSES):
                found, n, depth, moved = worst_contact(colliders, c, i, x0, x,
                                                       colliders.thickness[c], least)
                if not found:
                    break
                if ti.static(with_friction):
                    x, v = _friction(colliders, c, x + depth * n, x0, n, depth, moved / dt, dt)
                else:
                    x += depth * n
                touched = True
                least = RESOLVED * colliders.thickness[c]
    if not animated:
        d, n = collider_distance(colliders, c, x, x0)
        depth = colliders.thickness[c] - d
        if ti.static(with_friction):
            if depth > 0:
                x += depth * n
                x, v = _friction(colliders, c, x, x0, n, depth,
                                 surface_velocity(colliders, c, x, dt), dt)
                touched = True
        else:
            x += ti.max(depth, 0.0) * n
    return x, v, touched


@ti.func
def resolve_particle(model: ti.template(), state: ti.template(), colliders: ti.template(), i,
                     x0, dt):
    """Project particle i (if free) out of every collider, in collider order, with Coulomb
    friction on its displacement over the step (from x0, its position at the step's start)
    relative to the surface (colliders.py, _collide_with)."""
    if model.particle_inv_mass[i] > 0:
        x = state.particle_position[i]
        v = state.particle_velocity[i]
        touched = False
        for c in range(colliders.count):
            x, v, hit = _collide_with(colliders, c, i, x0, x, v, dt, True)
            touched = touched or hit
        colliders.touched[i] = ti.cast(touched, ti.i32)
        if touched:
            state.particle_position[i] = x
            state.particle_velocity[i] = v
            state.particle_prev_position[i] = x - v * dt


@ti.func
def resolve(model: ti.template(), state: ti.template(), colliders: ti.template(), i,
            now: ti.template()):
    """resolve_particle for particle i, from where it was at the step's start; marked for
    the first pass over the cloth's edges (animated_edges.py)."""
    resolve_particle(model, state, colliders, i, colliders.step_start[i], now.dt)
    if ti.static(colliders.edge_contact):
        colliders.edges.moved[i] = 1
        colliders.edges.shifted[i] = 0


@ti.func
def resolve_shifted(model: ti.template(), state: ti.template(), colliders: ti.template(), i,
                    now: ti.template()):
    """resolve_particle again for particle i if a pass over the cloth's edges moved it: an
    edge's move takes no account of the body's faces, and at a large step a cloth edge
    pushed off a body's edge carried its particles into the faces beside it (a 0.4 m box
    turning at 6 rad/s under a sheet, steps of 1/60 s: a particle inside the box in 109 of
    120 steps, 19 mm deep, and none with this; docs/performance.md). Once, after the last
    pass: after each pass instead, the box gave the same and the cape's preview cost no
    less."""
    if colliders.edges.shifted[i]:
        resolve_particle(model, state, colliders, i, colliders.step_start[i], now.dt)


@ti.func
def rests_on(colliders: ti.template(), i, x, reach):
    """Whether particle i, at x, rests on a collider: the step's response pushed it out of one
    (resolve_particle: an animated body's contact, found per triangle, included), or it is
    within `reach` [m] of a collider's contact surface (its thickness out from its shape;
    animated bodies are not asked, their distance being a search): what holds a layer up
    (self_collision.py, stacking)."""
    resting = colliders.touched[i] != 0
    if not resting:                                  # touched: no distance needed
        resting = near_surface(colliders, i, x, reach)
    return resting


@ti.func
def near_surface(colliders: ti.template(), i, x, reach):
    """Whether particle i, at x, is within `reach` [m] of a collider's contact surface
    (animated bodies are not asked: rests_on)."""
    near = False
    for c in range(colliders.count):
        if colliders.kind[c] != ANIMATED:
            d, _ = collider_distance(colliders, c, x, colliders.step_start[i])
            if d - colliders.thickness[c] < reach:
                near = True
    return near


@ti.func
def taken_at(colliders: ti.template(), i, x):
    """Whether particle i, put back at x (where it started the step) and left there, would
    be in a collider at the step's end: nearer than its thickness to the surface (less
    RESOLVED of it: a particle resting on it is not), or, for an animated body, met by it on
    the way (a body that swept over x: the continuous test of animated_contact.py on the
    still path x -> x). For stages that put particles back (contact/never_through.py)."""
    taken = False
    for c in range(colliders.count):
        if not taken:
            animated = False
            if ti.static(colliders.animated):
                animated = colliders.kind[c] == ANIMATED
                if animated:
                    found, _, _, _ = worst_contact(colliders, c, i, x, x, colliders.thickness[c],
                                                   RESOLVED * colliders.thickness[c])
                    taken = found
            if not animated:
                d, _ = collider_distance(colliders, c, x, x)
                taken = d < (1.0 - RESOLVED) * colliders.thickness[c]
    return taken


@ti.func
def push_out(model: ti.template(), state: ti.template(), colliders: ti.template(), i):
    """Project particle i (if free) out of every collider, position only (no friction, the
    velocity left to the caller): for what moves particles after the collision stage
    (self-collision's passes) or before it (xpbd's passes, where self-collision joins the
    solve: SelfCollision.in_solve) and must not push them into a collider."""
    if model.particle_inv_mass[i] > 0:
        x = state.particle_position[i]
        v = state.particle_velocity[i]
        for c in range(colliders.count):
            x, v, _ = _collide_with(colliders, c, i, colliders.step_start[i], x, v, 1.0, False)
        state.particle_position[i] = x


@ti.func
def project_particle_out(model: ti.template(), state: ti.template(), colliders: ti.template(),
                         i, applying: ti.template()):
    """push_out while applying[None]."""
    if applying[None]:
        push_out(model, state, colliders, i)


@backend.kernel
def measure_distances(colliders: ti.template(), points: ti.types.ndarray(),
                      distance: ti.types.ndarray(), normal: ti.types.ndarray()):
    """distance[p, c], normal[p, c] of points[p] from collider c (ColliderSet.distance)."""
    for p, c in ti.ndrange(points.shape[0], colliders.count):
        x = ti.Vector([points[p, 0], points[p, 1], points[p, 2]])
        d, n = collider_distance(colliders, c, x, x)
        distance[p, c] = d
        for k in ti.static(range(3)):
            normal[p, c, k] = n[k]
