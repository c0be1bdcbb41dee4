"""Cloth edges against the edges of animated meshes (animated_mesh.py, issue 38).

animated_contact.py keeps every particle thickness away from a body's triangles; a sharp
edge of the body (a shin, a shoulder's ridge, the rim of a box) can still pass between two
such particles, through the cloth edge joining them. So after the particles' contacts, every
cloth edge is tested against the body edges of the triangles whose swept boxes meet its own:
each body edge once, by the first of its triangles in the hierarchy's order, and only the
edges sharp enough to reach across a cloth edge unless edge_contact=True (`tested`,
animated_bodies.tested_edges); the triangles are found as the particles find theirs,
through candidate lists kept while the edge's two particles stay within a skin of where they
were (animated_contact.py). The test (geometry.edge_contact, the one self-collision makes of
two cloth edges; Bridson et al. 2002, section 6.2): the closest points at the step's end,
interior to both edges, nearer than the thickness or on the other side of each other than at
the step's start.

The deepest contact is answered as a one-sided position-based constraint
C = distance - thickness >= 0 on the cloth edge's two particles, the body's mass infinite:
particle k, with gradient weight g = (1 - s, s) and inverse mass w_k, moves by
-w_k g_k C n / W, W = w_i g_i^2 + w_j g_j^2 (Müller et al. 2007, eq. 8-9), W no less than
(w_i + w_j) / 4: a contact near a pinned end would otherwise swing the free end by C / g,
without bound as the contact nears the pin; the floor holds that lever to 2 (it never binds
for two free particles of equal mass). Each particle takes the mean of its edges' moves,
gathered in edge order (no atomics: reruns and thread counts give the same bits), and its
velocity loses what approaches the body along the move, relative to the mean velocity of the
body points it touched (the colliders' "no approach velocity", colliders.py; adding dx / dt
instead flings a particle pushed out of a fresh contact). Edge contacts take no friction: the
particles' own contacts carry it. The mean under-corrects a particle whose edges push it
different ways (one sitting on a ridge), so the pass runs EDGE_PASSES times, each after the
first only over edges whose particles the pass before moved: on a blade's edge the gap left
is then under 2 % of the thickness, 19 % after one pass. The passes end with the particles
they moved resolved against the colliders again (collision.resolve_shifted): an edge's move
knows nothing of the body's faces, and at a large step it carried particles into the faces
beside the edge. Edges whose spring tore, and bodies with no tested edge, are skipped.

Not covered: a body's vertex (a cone's tip) through the inside of a cloth triangle.
"""

import numpy as np
import taichi as ti

from ...geometry import edge_contact
from ...runtime import backend
from ...runtime.transfer import upload
from ..broad_phase.contact_pairs import cloth_edges, torn_edge
from .animated_contact import RESOLVED
from .candidate_lists import CandidateLists, stale_list, visit_near

EDGE_LISTED = 64    # candidate triangles an edge keeps per body (a path's box is longer)
EDGE_PASSES = 3     # passes over the edges a step (each particle takes its contacts' mean)


@backend.kernel_argument
class EdgeContacts:
    """A cloth's edges for contact with animated meshes: each edge's particles and spring,
    each edge's moves of its two ends (move[2 e + k]), whether it touched and the velocity of
    the body point it touched over the step (surface[e]); per particle whether the last pass
    moved it (moved[i]), whether any pass of the step did (shifted[i]) and the slots 2 e + k
    that move it (CSR in edge order:
    slot[start[i]:start[i + 1]]); and the edges' candidate lists (`bodies` animated bodies)."""

    def __init__(self, cloth, bodies: int):
        self.count = len(cloth_edges(cloth)[0])
        self.particle_count = cloth.particle_count
        real = backend.real()
        fields = backend.FieldGroup()
        self.edges = fields.vector(2, ti.i32, max(self.count, 1))
        self.edge_spring = fields.scalar(ti.i32, max(self.count, 1))
        self.move = fields.vector(3, real, max(2 * self.count, 1))
        self.touched = fields.scalar(ti.i32, max(self.count, 1))
        self.surface = fields.vector(3, real, max(self.count, 1))
        self.start = fields.scalar(ti.i32, self.particle_count + 1)
        self.slot = fields.scalar(ti.i32, max(2 * self.count, 1))
        self.moved = fields.scalar(ti.i32, self.particle_count)
        self.shifted = fields.scalar(ti.i32, self.particle_count)
        fields.finalize(self)
        self.lists = CandidateLists(max(self.count, 1) * bodies, 2, EDGE_LISTED)
        self.load(cloth, bodies)

    @staticmethod
    def structure(cloth, bodies: int) -> tuple:
        return ("EdgeContacts", len(cloth_edges(cloth)[0]), cloth.particle_count, bodies,
                EDGE_LISTED)

    def load(self, cloth, bodies: int) -> None:
        """Upload the cloth's edges, springs and particles' slots; every list made anew."""
        self.lists.forget()
        edges, springs = cloth_edges(cloth)
        ends = edges.ravel()
        start = np.zeros(self.particle_count + 1, np.int64)
        start[1:] = np.cumsum(np.bincount(ends, minlength=self.particle_count))
        if self.count:
            upload(((self.edges, edges), (self.edge_spring, springs),
                    (self.slot, np.argsort(ends, kind="stable"))))
        upload(((self.start, start),))


@ti.func
def edge_against_bodies(model: ti.template(), state: ti.template(), colliders: ti.template(), e,
                        now: ti.template()):
    """Cloth edge e against every animated body's edges (module doc): its ends' moves. Only
    an edge one of whose particles is marked moved: every particle for the step's first pass
    (the particles' contact phase marks them), then those the pass before moved (the others
    stand where it found them clear)."""
    edges, bodies = colliders.edges, colliders.bodies
    lists = edges.lists
    i, j = edges.edges[e][0], edges.edges[e][1]
    wi, wj = model.particle_inv_mass[i], model.particle_inv_mass[j]
    touched = 0
    moved = edges.moved[i] != 0 or edges.moved[j] != 0
    if moved and wi + wj > 0 and not torn_edge(edges, state, e):
        a0, b0 = colliders.step_start[i], colliders.step_start[j]
        a, b = state.particle_position[i], state.particle_position[j]
        lo, hi = ti.min(a0, b0, a, b), ti.max(a0, b0, a, b)
        # the deepest contact's gap, its normal (3), its parameter on e, the body point's
        # displacement (3)
        found = ti.Vector([0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        for body in range(bodies.count):
            if bodies.edge_contact[body]:
                thickness = colliders.thickness[bodies.collider[body]]
                slot = e * bodies.count + body
                skin = bodies.skin * thickness
                stale = (stale_list(bodies, lists, slot, body, 0, a0, a, skin)
                         or stale_list(bodies, lists, slot, body, 1, b0, b, skin))
                query = ti.Vector([a0[0], a0[1], a0[2], b0[0], b0[1], b0[2], a[0], a[1], a[2],
                                   b[0], b[1], b[2], thickness])
                found = visit_near(bodies, lists, slot, body, lo, hi, stale, skin, _consider,
                                   query, found, True)
                if stale:
                    lists.anchor[2 * slot] = a
                    lists.anchor[2 * slot + 1] = b
        deepest = found[0]
        if deepest < 0.0:
            normal = ti.Vector([found[1], found[2], found[3]])
            gi, gj = 1.0 - found[4], found[4]
            weight = ti.max(wi * gi * gi + wj * gj * gj, 0.25 * (wi + wj))
            edges.move[2 * e] = -wi * gi * deepest * normal / weight
            edges.move[2 * e + 1] = -wj * gj * deepest * normal / weight
            edges.surface[e] = ti.Vector([found[5], found[6], found[7]]) / now.dt
            touched = 1
    edges.touched[e] = touched


@ti.func
def _consider(bodies: ti.template(), f, query, found):
    """The edges triangle f owns against the cloth edge of `query` (its ends at the step's
    start, at its end, the thickness): edge_against_bodies's `found` replaced by a deeper
    contact."""
    a0 = ti.Vector([query[0], query[1], query[2]])
    b0 = ti.Vector([query[3], query[4], query[5]])
    a = ti.Vector([query[6], query[7], query[8]])
    b = ti.Vector([query[9], query[10], query[11]])
    thickness = query[12]
    lo = ti.min(a0, b0, a, b) - thickness
    hi = ti.max(a0, b0, a, b) + thickness
    corner = bodies.triangles[f]
    for side in range(3):
        u, v = corner[side], corner[(side + 1) % 3]
        u0, v0, u1, v1 = bodies.start[u], bodies.start[v], bodies.end[u], bodies.end[v]
        if (bodies.tested[f][side] and (ti.min(u0, v0, u1, v1) <= hi).all()
                and (lo <= ti.max(u0, v0, u1, v1)).all()):
            hit, n, gap, s, t = edge_contact(a, b, u1, v1, a0, b0, u0, v0, thickness)
            if hit and gap < found[0] and gap < -RESOLVED * thickness:
                moved = (1.0 - t) * (u1 - u0) + t * (v1 - v0)
                found[0], found[4] = gap, s
                for k in ti.static(range(3)):
                    found[1 + k] = n[k]
                    found[5 + k] = moved[k]
    return found


@ti.func
def follow_edges(model: ti.template(), state: ti.template(), colliders: ti.template(), i,
                 now: ti.template()):
    """Particle i moved by the mean of its touched edges' moves, without approach velocity
    along it relative to the body points they touched."""
    edges = colliders.edges
    edges.moved[i] = 0
    if model.particle_inv_mass[i] > 0:
        move = ti.Vector([0.0, 0.0, 0.0])
        surface = ti.Vector([0.0, 0.0, 0.0])
        contacts = 0
        for a in range(edges.start[i], edges.start[i + 1]):
            slot = edges.slot[a]
            if edges.touched[slot // 2]:
                move += edges.move[slot]
                surface += edges.surface[slot // 2]
                contacts += 1
        length = move.norm()
        if contacts > 0 and length > 0.0:
            x = state.particle_position[i] + move / contacts
            v = state.particle_velocity[i]
            n = move / length
            approach = (v - surface / contacts).dot(n)
            if approach < 0.0:
                v -= approach * n
            state.particle_position[i] = x
            edges.moved[i] = edges.shifted[i] = 1
            state.particle_velocity[i] = v
            state.particle_prev_position[i] = x - v * now.dt
