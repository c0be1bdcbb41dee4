"""Self-collision and cloth-on-cloth (self_collision.py), checked against independent geometry
written here: brute-force point-triangle distances and segment-triangle intersections."""

import numpy as np
import pytest

import ti_cloth as tc

THICKNESS = 0.01


def point_triangle_distances(points, corners):
    """Distance from points[k] to triangle corners[k] (K, 3, 3): the plane distance where the
    foot is inside, else the nearest of the three edges."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    height = np.einsum("kd,kd->k", points - a, normal)
    foot = points - height[:, None] * normal
    inside = np.ones(len(points), bool)
    for p, q in ((a, b), (b, c), (c, a)):                             # same side of every edge
        inside &= np.einsum("kd,kd->k", np.cross(q - p, foot - p), normal) >= 0
    best = np.where(inside, np.abs(height), np.inf)
    for p, q in ((a, b), (b, c), (c, a)):
        d = q - p
        s = np.clip(np.einsum("kd,kd->k", points - p, d) / (d * d).sum(1), 0, 1)
        best = np.minimum(best, np.linalg.norm(points - (p + s[:, None] * d), axis=1))
    return best


def segments_cross_triangles(ends, corners):
    """Whether segment ends[k] (K, 2, 3) passes through triangle corners[k] (K, 3, 3), strictly
    inside both (Moller-Trumbore)."""
    p, q = ends[:, 0], ends[:, 1]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2, d = b - a, c - a, q - p
    h = np.cross(d, e2)
    det = np.einsum("kd,kd->k", h, e1)
    ok = np.abs(det) > 1e-14
    det = np.where(ok, det, 1.0)
    s = p - a
    u = np.einsum("kd,kd->k", s, h) / det
    qv = np.cross(s, e1)
    v = np.einsum("kd,kd->k", qv, d) / det
    t = np.einsum("kd,kd->k", qv, e2) / det
    return ok & (u > 0) & (v > 0) & (u + v < 1) & (t > 0) & (t < 1)


def violations(cloth, x):
    """(closest vertex-triangle distance over pairs sharing no particle, or inf beyond
    THICKNESS; how many edges pass through a triangle they share no particle with), brute force
    over the pairs whose bounding boxes (grown by THICKNESS) meet."""
    tris = cloth.mesh.triangles
    corners = x[tris]
    lo, hi = corners.min(axis=1) - THICKNESS, corners.max(axis=1) + THICKNESS
    near = ((x[:, None] >= lo[None]) & (x[:, None] <= hi[None])).all(axis=2)
    near &= ~(np.arange(len(x))[:, None, None] == tris[None]).any(axis=2)
    v, t = np.nonzero(near)
    closest = point_triangle_distances(x[v], corners[t]).min() if len(v) else np.inf
    edges = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), 1),
                      axis=0)
    ends = x[edges]
    meets = ((ends.min(axis=1)[:, None] <= hi[None]) & (ends.max(axis=1)[:, None] >= lo[None])).all(axis=2)
    meets &= ~(edges[:, None, :, None] == tris[None, :, None, :]).any(axis=(2, 3))
    e, t = np.nonzero(meets)
    crossings = int(segments_cross_triangles(ends[e], corners[t]).sum()) if len(e) else 0
    return float(closest), crossings


def two_sheets():
    """A 12 x 12 sheet pinned flat at y = 0 and a free 12 x 12 sheet 0.2 m above it."""
    lower = tc.Cloth(tc.grid_mesh(12, 12, size=(1.0, 1.0), plane="xz"), tc.Material(),
                     pinned=np.arange(144))
    mesh = tc.grid_mesh(12, 12, size=(0.8, 0.8), plane="xz")
    upper = tc.Cloth(tc.Mesh(mesh.vertices + [0.1, 0.2, 0.1], mesh.triangles), tc.Material())
    return tc.Cloth.combine([lower, upper])


@pytest.mark.slow
def test_a_sheet_dropped_on_another_rests_on_it_and_never_passes_through(f64):
    """Every 1/60 s of a 1 s fall and rest (xpbd, 1/240 s steps): no vertex nearer than half
    the thickness to a triangle it is not a corner of, no edge through a triangle; at the end
    the upper sheet lies one thickness above the lower. Without self-collision it falls through."""
    body = two_sheets()
    worst = []
    sim = tc.Simulation(body, integrator="xpbd", dt=1 / 240, self_collision=tc.SelfCollision(THICKNESS))
    for _ in range(60):
        sim.step(4)
        worst.append(violations(body, sim.positions()))
    closest, crossings = min(w[0] for w in worst), max(w[1] for w in worst)
    upper = sim.positions()[144:, 1]
    print(f"closest vertex-triangle {closest:.4g} m, edge crossings {crossings}, upper sheet at "
          f"{upper.min():.4g}..{upper.max():.4g} m")
    assert closest > 0.5 * THICKNESS and crossings == 0
    assert np.abs(upper - THICKNESS).max() < 0.2 * THICKNESS
    free = tc.Simulation(body, integrator="xpbd", dt=1 / 240)
    free_worst = []
    for _ in range(60):
        free.step(4)
        free_worst.append(violations(body, free.positions()))
    assert min(w[0] for w in free_worst) < 0.5 * THICKNESS, "the same check fails without it"
    assert free.positions()[144:, 1].max() < -0.5, "without self-collision it falls through"


@pytest.mark.parametrize("kwargs, field", [({"thickness": 0.0}, "SelfCollision.thickness"),
                                           ({"thickness": float("nan")}, "SelfCollision.thickness"),
                                           ({"iterations": 0}, "SelfCollision.iterations")])
def test_bad_settings_are_refused_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        tc.SelfCollision(**kwargs)
    with pytest.raises(ValueError, match="self_collision must be None or a SelfCollision"):
        tc.Simulation(tc.string(3, 1.0), self_collision=0.01)


def test_one_thread_and_two_and_a_rerun_give_the_same_bits():
    """Contacts are listed in index order and gathered per particle in list order."""
    from ti_cloth import backend
    body = two_sheets()
    runs = []
    try:
        for threads in (1, 2, 2):
            if not runs or backend.cpu_threads() != threads:
                tc.init(arch="cpu", precision="f64", threads=threads)
            sim = tc.Simulation(body, integrator="xpbd", dt=1 / 240,
                                self_collision=tc.SelfCollision(THICKNESS))
            sim.step(60)
            runs.append(sim.positions())
    finally:
        tc.init(arch="cpu", precision="f64")
    np.testing.assert_array_equal(runs[0], runs[1])
    np.testing.assert_array_equal(runs[1], runs[2])
    assert runs[0][144:, 1].max() < 0.1, "the sheet reached the other"


@pytest.mark.slow
def test_a_ribbon_folded_onto_itself_stays_two_layers(f64):
    """A 1.2 m ribbon on the ground, its end carried over it by a handle (1 s), so the lifted
    part folds down onto the rest: in every frame no vertex nearer than half the thickness to a
    triangle of the ribbon it is not a corner of and no edge through a triangle. Without
    self-collision the folded layer lands in the lower one (distance 0, edges through)."""
    cloth = tc.Cloth(tc.grid_mesh(4, 30, size=(1.2, 0.15), plane="xz"), tc.Material())
    end = np.flatnonzero(np.isclose(cloth.particle_position[:, 0], 1.2))

    def carried(t):
        s = min(t, 1.0)
        return (-0.9 * s, 0.12 * np.sin(np.pi * s), 0.0)

    worst = {}
    for contact in (tc.SelfCollision(THICKNESS), None):
        sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 240, self_collision=contact,
                            handles=[tc.Handle(end, carried)],
                            colliders=[tc.Plane(point=(0.0, -0.01, 0.0), static_friction=0.5)])
        frames = []
        for _ in range(75):
            sim.step(4)
            frames.append(violations(cloth, sim.positions()))
        worst[contact is not None] = (min(f[0] for f in frames), max(f[1] for f in frames))
    print(f"closest vertex-triangle, most edge crossings (with, without): {worst}")
    assert worst[True][0] > 0.5 * THICKNESS and worst[True][1] == 0
    assert worst[False][0] < 0.5 * THICKNESS and worst[False][1] > 0
