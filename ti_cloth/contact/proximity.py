"""Closest points between segments, and between a point and a triangle (Ericson, Real-Time
Collision Detection, 5.1.5 and 5.1.9): the distances self-collision's candidate pairs are
chosen by. Degenerate input (a zero-length segment, a triangle of zero area) gives the
distance to what is left of it, never NaN."""

import taichi as ti

TINY = 1e-30     # keeps a zero squared length from dividing


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
def _point_segment_distance(p, a, b):
    d = b - a
    s = ti.math.clamp((p - a).dot(d) / ti.max(d.dot(d), TINY), 0.0, 1.0)
    return (p - a - s * d).norm()


@ti.func
def triangle_distance(p, a, b, c):
    """The distance from point p to triangle abc (5.1.5: the Voronoi region of p's closest
    feature, a corner, an edge or the face)."""
    ab, ac = b - a, c - a
    d1, d2 = ab.dot(p - a), ac.dot(p - a)
    d3, d4 = ab.dot(p - b), ac.dot(p - b)
    d5, d6 = ab.dot(p - c), ac.dot(p - c)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    closest = a
    if d1 <= 0.0 and d2 <= 0.0:
        closest = a
    elif d3 >= 0.0 and d4 <= d3:
        closest = b
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        closest = a + d1 / (d1 - d3) * ab
    elif d6 >= 0.0 and d5 <= d6:
        closest = c
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        closest = a + d2 / (d2 - d6) * ac
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        closest = b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
    else:
        area = va + vb + vc
        if area > 0.0:
            closest = a + (vb / area) * ab + (vc / area) * ac
    distance = (p - closest).norm()
    if not va + vb + vc > 0.0:          # no area: the nearest of its three edges
        distance = ti.min(_point_segment_distance(p, a, b), _point_segment_distance(p, b, c),
                          _point_segment_distance(p, c, a))
    return distance
