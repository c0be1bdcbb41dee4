"""The narrow phase of contact with animated (deforming) meshes (animated_mesh.py; their
placement: animated_bodies.py; the triangles a path may meet: candidate_lists.py).

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
"""


import taichi as ti

from ...geometry import foot_barycentric, nearest_on_edges
from .candidate_lists import stale_list, visit_near

PASSES = 4          # contacts answered per particle and body in a step, at most
RESOLVED = 1e-4     # after the first, contacts shallower than this (in thicknesses) are left
INSIDE = 1e-4       # a point this far outside a triangle (barycentric) still meets it
BISECTIONS = 40     # halvings of a crossing's time interval


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
