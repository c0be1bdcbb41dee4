"""The shared geometry (ti_cloth/geometry.py) against an independent computation: the
closest point found by enumerating a triangle's or segment pair's features (the KKT cases:
interior, edges, corners; each the projection on the feature's affine hull, kept if it lies
in the feature), where geometry.py decides by Voronoi regions; and the Taichi routines
against their numpy twins."""

import numpy as np
import taichi as ti
from helpers import report

from ti_cloth import geometry


def on_segment(p, a, b):
    """The point of segment ab nearest p (projection on the line, clamped)."""
    d = b - a
    s = 0.0 if d @ d == 0 else np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return a + s * d


def nearest_on_triangle(p, a, b, c):
    """KKT enumeration: the face's interior (the plane's foot, if its coordinates are all
    positive), then every edge and corner; the nearest feasible candidate."""
    candidates = [on_segment(p, u, v) for u, v in ((a, b), (b, c), (c, a))]
    e1, e2 = b - a, c - a
    gram = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
    if abs(np.linalg.det(gram)) > 1e-12 * gram[0, 0] * gram[1, 1]:
        u, v = np.linalg.solve(gram, [(p - a) @ e1, (p - a) @ e2])
        if u >= 0 and v >= 0 and u + v <= 1:
            candidates.append(a + u * e1 + v * e2)
    return min(candidates, key=lambda q: np.linalg.norm(p - q))


def segments_distance(p1, q1, p2, q2):
    """KKT enumeration: both interiors (the 2x2 normal equations), then each end against
    the other segment."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    pairs = [(x, on_segment(x, p2, q2)) for x in (p1, q1)]
    pairs += [(on_segment(y, p1, q1), y) for y in (p2, q2)]
    gram = np.array([[d1 @ d1, -d1 @ d2], [-d1 @ d2, d2 @ d2]])
    if abs(np.linalg.det(gram)) > 1e-9 * gram[0, 0] * gram[1, 1]:
        s, t = np.linalg.solve(gram, [-d1 @ r, d2 @ r])
        if 0 <= s <= 1 and 0 <= t <= 1:
            pairs.append((p1 + s * d1, p2 + t * d2))
    return min(np.linalg.norm(x - y) for x, y in pairs)


def random_cases(count, seed):
    """Points and triangles around the unit cube, some triangles squeezed flat or to a point,
    some points in the triangle's plane."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1.0, 1.0, (count, 4, 3))
    points[::7, 3] = points[::7, 2]                                 # two corners coincide
    points[3::11, 3] = 0.5 * (points[3::11, 1] + points[3::11, 2])  # corners in a line
    plane = points[5::9]
    plane[:, 0] = plane[:, 1] + 0.7 * (plane[:, 2] - plane[:, 1]) - 0.6 * (plane[:, 3] - plane[:, 1])
    return points


@ti.kernel
def _evaluate(x: ti.types.ndarray(ndim=3), out: ti.types.ndarray(ndim=2)):
    for k in range(x.shape[0]):
        p = ti.Vector([x[k, 0, 0], x[k, 0, 1], x[k, 0, 2]], ti.f64)
        a = ti.Vector([x[k, 1, 0], x[k, 1, 1], x[k, 1, 2]], ti.f64)
        b = ti.Vector([x[k, 2, 0], x[k, 2, 1], x[k, 2, 2]], ti.f64)
        c = ti.Vector([x[k, 3, 0], x[k, 3, 1], x[k, 3, 2]], ti.f64)
        n, h, w = geometry.point_over_triangle(p, a, b, c)
        foot, m = geometry.foot_barycentric(p, a, b, c)
        q, edge_w = geometry.nearest_on_edges(p, a, b, c)
        values = ti.Vector([geometry.triangle_distance(p, a, b, c),
                            geometry.segment_distance(p, a, b, c), h,
                            w[0], w[1], w[2], n[0], n[1], n[2], foot[0], foot[1], foot[2],
                            q[0], q[1], q[2], edge_w[0], edge_w[1], edge_w[2], m.norm()], ti.f64)
        for j in ti.static(range(19)):
            out[k, j] = values[j]


def evaluate(points):
    out = np.zeros((len(points), 19))
    _evaluate(points, out)
    return out


def test_distances_match_an_enumeration_of_features(f64):
    points = random_cases(400, 1)
    got = evaluate(points)
    expected_triangle = [np.linalg.norm(p - nearest_on_triangle(p, a, b, c)) for p, a, b, c in points]
    expected_segments = [segments_distance(*case) for case in points]
    worst = np.abs(got[:, 0] - expected_triangle).max()
    report("point-triangle distance, worst difference [m]", worst, "< 1e-12")
    assert worst < 1e-12
    worst = np.abs(got[:, 1] - expected_segments).max()
    report("segment-segment distance, worst difference [m]", worst, "< 1e-9")
    assert worst < 1e-9


def test_a_point_over_a_triangle_and_its_numpy_twin(f64):
    points = random_cases(400, 2)
    got = evaluate(points)
    p, a, b, c = (points[:, i] for i in range(4))
    n, h, wb, wc, has_area = geometry.points_over_triangles(p, a, b, c)
    assert has_area[::7].sum() == 0 and has_area[3::11].sum() == 0 and has_area.sum() > 300
    np.testing.assert_allclose(got[:, 2], h, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got[:, 6:9], n, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got[:, 4:6], np.column_stack([wb, wc]), rtol=0, atol=1e-12)
    # the foot p - h n is the barycentric combination; both routines agree where there is area
    w = got[has_area, 3:6]
    feet = np.einsum("pk,pkj->pj", w, points[has_area, 1:])
    np.testing.assert_allclose(feet, (p - h[:, None] * n)[has_area], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[has_area, 9:12], w, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[has_area, 18], np.linalg.norm(np.cross(b - a, c - a), axis=1)[has_area],
                               rtol=1e-14)
    # in-plane points have height 0
    assert np.abs(got[5::9, 2][has_area[5::9]]).max() < 1e-12
    # no area: zero normal, height and weights; the foot falls back to the first corner
    assert not got[~has_area, 2:9].any()
    np.testing.assert_array_equal(got[~has_area, 9:12], np.tile([1.0, 0.0, 0.0], ((~has_area).sum(), 1)))


def test_nearest_points_of_the_edges_and_of_the_triangle(f64):
    points = random_cases(400, 3)
    got = evaluate(points)
    for k, (p, a, b, c) in enumerate(points):
        nearest = min((on_segment(p, u, v) for u, v in ((a, b), (b, c), (c, a))),
                      key=lambda q: np.linalg.norm(p - q))
        assert np.linalg.norm(got[k, 12:15] - nearest) < 1e-12, k
        np.testing.assert_allclose(got[k, 15:18] @ np.stack([a, b, c]), got[k, 12:15], atol=1e-12)
    # the host's closest point on a triangle (an attachment's binding), on triangles with area
    p, a, b, c = (points[:, i] for i in range(4))
    fine = np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-6
    w = geometry.closest_barycentric(a[fine], b[fine], c[fine], p[fine])
    expected = [nearest_on_triangle(*case) for case in points[fine]]
    assert np.abs(w.sum(axis=1) - 1).max() < 1e-12 and w.min() >= 0
    np.testing.assert_allclose(np.einsum("pk,pkj->pj", w, points[fine, 1:]), expected, atol=1e-12)

