"""Geometry that forces, contact and attachments share, written once: a point over a triangle's
plane (the unit normal, its signed height, its foot's barycentric coordinates), the nearest
point of a triangle or of its edges, the closest points of two segments (Ericson, Real-Time
Collision Detection, 3.4, 5.1.5 and 5.1.9) and the contact of two moving edges. Taichi
functions, with numpy twins where the host needs the same answer (the altitude springs' rest
heights, an attachment's binding).

Degenerate input (a zero-length segment, a triangle of zero area) gives the distance to what
is left of it, or a zero normal, never NaN.
"""

import numpy as np
import taichi as ti

TINY = 1e-30     # keeps a zero squared length from dividing


@ti.func
def in_plane(q, e1, e2, normal, scale):
    """Barycentric coordinates (1 - u - v, u, v) of the point a + q of the plane of triangle
    (a, a + e1, a + e2): u = (q x e2) . normal / scale, v = (e1 x q) . normal / scale, for a
    normal m = e1 x e2 with scale = |m|^2, or the unit normal m / |m| with scale = |m|."""
    u = q.cross(e2).dot(normal) / scale
    v = e1.cross(q).dot(normal) / scale
    return ti.Vector([1.0 - u - v, u, v])


@ti.func
def foot_barycentric(p, a, b, c):
    """(w, m): the barycentric coordinates w of p's foot on the plane of abc, and abc's
    unnormalised normal m = (b - a) x (c - a) (zero for a degenerate triangle, whose
    coordinates are then (1, 0, 0))."""
    e1, e2 = b - a, c - a
    m = e1.cross(e2)
    area2 = m.dot(m)
    w = ti.Vector([1.0, 0.0, 0.0])
    if area2 > 0:
        w = in_plane(p - a, e1, e2, m, area2)
    return w, m


@ti.func
def point_over_triangle(xp, xa, xb, xc):
    """(n, h, w) of point p over triangle abc: n = (x_b - x_a) x (x_c - x_a) / |...| the unit
    normal, h = (x_p - x_a) . n the signed height of p over the plane, w = (w_a, w_b, w_c) the
    barycentric coordinates of p's foot. The gradient of h is (n, -w_a n, -w_b n, -w_c n) over
    (p, a, b, c) (the foot's tangential terms cancel). A face of zero area has no normal:
    n = 0, h = 0, w = 0."""
    e1, e2, u = xb - xa, xc - xa, xp - xa
    normal = e1.cross(e2)
    area2 = normal.norm()
    n = ti.Vector([0.0, 0.0, 0.0])
    w = ti.Vector([0.0, 0.0, 0.0])
    h = 0.0
    if area2 > 0:
        n = normal / area2
        h = u.dot(n)
        w = in_plane(u, e1, e2, n, area2)
    return n, h, w


def points_over_triangles(p, a, b, c):
    """Host twin of point_over_triangle for arrays of points p and triangles a b c (each
    (K, 3)): (n (K, 3), h (K,), wb (K,), wc (K,), has_area (K,)), with w_a = 1 - wb - wc.
    Zero normal, height and weights where a triangle has no area."""
    e1, e2, u = b - a, c - a, p - a
    normal = np.cross(e1, e2)
    area2 = np.linalg.norm(normal, axis=1)
    safe = np.where(area2 > 0, area2, np.inf)[:, None]
    n = normal / safe
    h = np.einsum("ij,ij->i", u, n)
    wb = np.einsum("ij,ij->i", np.cross(u, e2), n) / safe[:, 0]
    wc = np.einsum("ij,ij->i", np.cross(e1, u), n) / safe[:, 0]
    return n, h, wb, wc, area2 > 0


@ti.func
def nearest_on_edges(p, a, b, c):
    """(q, w): the point q of triangle abc's edges nearest p, and its barycentric coordinates."""
    best, weights = a, ti.Vector([1.0, 0.0, 0.0])
    distance = (p - a).norm_sqr() + 1.0
    corners = ti.Matrix.rows([a, b, c])
    for k in ti.static(range(3)):
        u, v = corners[k, :], corners[(k + 1) % 3, :]
        d = v - u
        s = ti.math.clamp((p - u).dot(d) / ti.max(d.dot(d), TINY), 0.0, 1.0)
        q = u + s * d
        if (p - q).norm_sqr() < distance:
            distance = (p - q).norm_sqr()
            best = q
            weights = ti.Vector([0.0, 0.0, 0.0])
            weights[k] = 1.0 - s
            weights[(k + 1) % 3] = s
    return best, weights


def closest_barycentric(a, b, c, points) -> np.ndarray:
    """(P, 3) barycentric coordinates of each point's nearest point on its triangle a b c
    (host, arrays (P, 3)): its foot in the plane when that is inside, else the nearest point
    of the nearest edge (Ericson 3.4 and 5.1.5)."""
    e0, e1, d = b - a, c - a, points - a
    d00, d01, d11 = (np.sum(x * y, axis=1) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.sum(d * e0, axis=1), np.sum(d * e1, axis=1)
    det = d00 * d11 - d01 * d01
    v, w = (d11 * d20 - d01 * d21) / det, (d00 * d21 - d01 * d20) / det
    result = np.column_stack([1 - v - w, v, w])
    outside = (result < 0).any(axis=1)
    corners = np.stack([a, b, c], axis=1)
    best = np.full(len(points), np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        p, q = corners[:, i], corners[:, j]
        s = np.clip(np.sum((points - p) * (q - p), axis=1) / np.sum((q - p) ** 2, axis=1), 0, 1)
        distance = np.linalg.norm(p + s[:, None] * (q - p) - points, axis=1)
        nearer = outside & (distance < best)
        best[nearer] = distance[nearer]
        result[nearer] = 0.0
        result[nearer, i], result[nearer, j] = 1 - s[nearer], s[nearer]
    return result


@ti.func
def segment_parameters(p1, q1, p2, q2):
    """Parameters (s, t) in [0, 1] of the closest points p1 + s (q1 - p1), p2 + t (q2 - p2)
    of two segments (5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = ti.max(d1.dot(d1), TINY), ti.max(d2.dot(d2), TINY), d2.dot(r)
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
def segment_distance(p1, q1, p2, q2):
    """The distance between segments p1 q1 and p2 q2."""
    s, t = segment_parameters(p1, q1, p2, q2)
    return (p1 + s * (q1 - p1) - p2 - t * (q2 - p2)).norm()


@ti.func
def edge_contact(a, b, c, d, a0, b0, c0, d0, thickness):
    """(in contact, n, gap, s, t) of the moving edges ab and cd, now at a b c d and at the
    step's start at a0 b0 c0 d0: their closest points now at parameters s and t, n the unit
    direction from cd's point to ab's on the side they were on at the start (a pair that
    crossed during the step is sent back), gap = distance along n minus thickness. In contact:
    both points interior to their edges and gap < 0 (an end's contacts are a vertex's)."""
    s, t = segment_parameters(a, b, c, d)
    between = a + s * (b - a) - c - t * (d - c)
    s0, t0 = segment_parameters(a0, b0, c0, d0)
    before = a0 + s0 * (b0 - a0) - c0 - t0 * (d0 - c0)
    distance = between.norm()
    n = between / ti.max(distance, TINY)
    if before.norm() > 0 and between.dot(before) < 0.0:
        n = -n                                       # crossed during the step: back to its side
    if distance == 0.0:
        n = before / ti.max(before.norm(), TINY)
    gap = between.dot(n) - thickness
    interior = s > 0.0 and s < 1.0 and t > 0.0 and t < 1.0
    return interior and gap < 0.0 and n.norm() > 0, n, gap, s, t


@ti.func
def point_segment_distance(p, a, b):
    """The distance from point p to segment ab."""
    d = b - a
    s = ti.math.clamp((p - a).dot(d) / ti.max(d.dot(d), TINY), 0.0, 1.0)
    return (p - a - s * d).norm()


@ti.func
def triangle_closest(p, a, b, c):
    """(the point of triangle abc nearest to p, its barycentric coordinates (w_a, w_b, w_c),
    whether the triangle has an area) (Ericson, "Real-time collision detection", 2005, 5.1.5:
    the Voronoi region of p's closest feature, a corner, an edge or the face). A triangle of no
    area may give a, (1, 0, 0)."""
    ab, ac = b - a, c - a
    d1, d2 = ab.dot(p - a), ac.dot(p - a)
    d3, d4 = ab.dot(p - b), ac.dot(p - b)
    d5, d6 = ab.dot(p - c), ac.dot(p - c)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    closest = a
    w = ti.Vector([1.0, 0.0, 0.0])
    if d1 <= 0.0 and d2 <= 0.0:
        closest = a
    elif d3 >= 0.0 and d4 <= d3:
        closest = b
        w = ti.Vector([0.0, 1.0, 0.0])
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        s = d1 / (d1 - d3)
        closest = a + s * ab
        w = ti.Vector([1.0 - s, s, 0.0])
    elif d6 >= 0.0 and d5 <= d6:
        closest = c
        w = ti.Vector([0.0, 0.0, 1.0])
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        s = d2 / (d2 - d6)
        closest = a + s * ac
        w = ti.Vector([1.0 - s, 0.0, s])
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        s = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        closest = b + s * (c - b)
        w = ti.Vector([0.0, 1.0 - s, s])
    elif va + vb + vc > 0.0:
        area = va + vb + vc
        closest = a + (vb / area) * ab + (vc / area) * ac
        w = ti.Vector([1.0 - (vb + vc) / area, vb / area, vc / area])
    return closest, w, va + vb + vc > 0.0


@ti.func
def triangle_distance(p, a, b, c):
    """The distance from point p to triangle abc (triangle_closest; a triangle of no area: the
    nearest of its three edges)."""
    closest, _, has_area = triangle_closest(p, a, b, c)
    distance = (p - closest).norm()
    if not has_area:
        distance = ti.min(point_segment_distance(p, a, b), point_segment_distance(p, b, c),
                          point_segment_distance(p, c, a))       # no area: its nearest edge
    return distance
