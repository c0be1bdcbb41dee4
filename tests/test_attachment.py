"""Attachments (contact/colliders/attachment.py): cloth particles carried by a collider's surface. The
surface point each particle should be at is computed here independently (its nearest triangle
found by brute force, barycentric coordinates by Cramer's rule), and rigid carrying is checked
against the shape's own transform."""


import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.inputs.scene_file import SceneError

ROUNDING = 1e-12        # f64 positions of order 1 m, a few operations: rounding only
SHEET = tc.grid_mesh(6, 6, (0.6, 0.6), plane="xz", origin=(-0.3, 0.0, -0.3))


def waving(t):
    """The sheet's vertices at time t, stretched, sheared, bent and turned: no rigid motion."""
    x, z = SHEET.vertices[:, 0], SHEET.vertices[:, 2]
    y = 0.1 * np.sin(3 * t) * np.cos(4 * x) + 0.2 * t
    x2 = x * (1 + 0.3 * t) + 0.2 * t * z
    angle = 0.8 * t
    return np.column_stack([np.cos(angle) * x2 + np.sin(angle) * z, y,
                            -np.sin(angle) * x2 + np.cos(angle) * z])


def brute_force_feet(vertices, triangles, points):
    """(nearest triangle, barycentric coordinates of the point's foot in it) for points lying
    on the surface: the triangle whose plane holds the point with all coordinates >= 0."""
    found = []
    for p in points:
        for k, (i, j, l) in enumerate(triangles):
            a, b, c = vertices[i], vertices[j], vertices[l]
            matrix = np.column_stack([b - a, c - a, np.cross(b - a, c - a)])
            u, v, w = np.linalg.solve(matrix, p - a)
            if abs(w) < 1e-9 and min(u, v, 1 - u - v) > -1e-9:
                found.append((k, np.array([1 - u - v, u, v])))
                break
        else:
            raise AssertionError(f"{p} is on no triangle")
    return found


def cloth_on_the_sheet(points):
    """A cloth of a few triangles whose particles are `points`."""
    mesh = tc.Mesh(points, np.array([[0, 1, 2], [1, 3, 2]]))
    return tc.Cloth(mesh, tc.Material())


def test_attached_particles_stay_on_their_triangles_to_rounding(f64):
    """Four particles at interior points of a deforming sheet stay at the same barycentric
    points of the same triangles through 0.5 s of stretching, shearing, bending and turning;
    without the attachment they fall away."""
    rng = np.random.default_rng(3)
    triangles = rng.choice(SHEET.triangle_count, 4, replace=False)
    weights = rng.dirichlet(np.ones(3), 4)
    corners = SHEET.vertices[SHEET.triangles[triangles]]
    points = np.einsum("pk,pkj->pj", weights, corners)
    collider = tc.AnimatedMeshCollider(SHEET, waving, thickness=0.0)
    feet = brute_force_feet(SHEET.vertices, SHEET.triangles, points)
    attached = tc.Simulation(cloth_on_the_sheet(points), integrator="xpbd", dt=1 / 600,
                             handles=[tc.Attachment([0, 1, 2, 3], collider)])
    free = tc.Simulation(cloth_on_the_sheet(points), integrator="xpbd", dt=1 / 600)
    worst, control = 0.0, 0.0
    for _ in range(10):
        attached.step(30)
        free.step(30)
        vertices = waving(attached.time)
        expected = np.array([w @ vertices[SHEET.triangles[k]] for k, w in feet])
        worst = max(worst, np.abs(attached.positions() - expected).max())
        control = max(control, np.abs(free.positions() - expected).max())
    report("attached particles off their surface points (m), free ones", (worst, control),
           f"< {ROUNDING}, > 0.1")
    assert worst < ROUNDING and control > 0.1
    v = attached.velocities()
    step = waving(attached.time) - waving(attached.time - attached.dt)
    expected_v = np.array([w @ step[SHEET.triangles[k]] for k, w in feet]) / attached.dt
    np.testing.assert_allclose(v, expected_v, rtol=0, atol=1e-9)


def test_a_particle_off_the_surface_keeps_its_offset_in_the_triangles_frame(f64):
    """Particles 2 cm above (and one beside) the sheet stay 2 cm off it along the moving
    triangle's normal, on the side they started."""
    points = np.array([[0.01, 0.02, 0.03], [0.13, 0.02, -0.05], [-0.05, -0.02, 0.1],
                       [0.35, 0.0, 0.0]])
    collider = tc.AnimatedMeshCollider(SHEET, waving)
    handle = tc.Attachment([0, 1, 2, 3], collider).handle(points)
    for t in (0.0, 0.2, 0.5):
        x = points + handle.path(t)
        vertices = waving(t)
        for p, k in zip(x[:3], handle.path.triangle[:3]):
            a, b, c = vertices[SHEET.triangles[k]]
            normal = np.cross(b - a, c - a)
            height = (p - a) @ normal / np.linalg.norm(normal)
            assert abs(abs(height) - 0.02) < ROUNDING
    beside = points[3] + handle.path(0.0)[3]
    np.testing.assert_allclose(beside, points[3], atol=ROUNDING)


def test_rigid_colliders_carry_attached_particles_with_their_own_motion(f64):
    """A sphere on a path and a turning mesh collider: the attached particles are where the
    shape's transform takes their rest positions."""
    def path(t):
        return np.array([0.3 * t, 0.1 * np.sin(5 * t), 0.0]) + (0.0, 0.05, 0.0)

    sphere = tc.Sphere(centre=(0.0, 0.0, 0.0), radius=0.2, path=path)
    box = tc.MeshCollider(tc.box_mesh((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2)), path=path,
                          rotation=lambda t: (0.0, 2.0 * t, 0.0))
    points = np.array([[0.0, 0.25, 0.0], [0.2, 0.05, 0.0], [0.0, 0.05, 0.2], [0.1, 0.2, 0.1]])
    for collider in (sphere, box):
        sim = tc.Simulation(cloth_on_the_sheet(points), integrator="symplectic_euler",
                            dt=1e-4, handles=[tc.Attachment([0, 1, 2, 3], collider)])
        sim.step(3000)
        t = sim.time
        if collider is sphere:
            expected = points + path(t) - path(0.0)
        else:
            angle = 2.0 * t
            turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                             [-np.sin(angle), 0, np.cos(angle)]])
            centre = path(0.0)     # the box's centre at t = 0
            expected = (points - centre) @ turn.T + path(t)
        report(type(collider).__name__, np.abs(sim.positions() - expected).max(), "rounding")
        np.testing.assert_allclose(sim.positions(), expected, rtol=0, atol=ROUNDING)


def test_a_released_attachment_lets_its_particles_fall_with_the_surfaces_velocity(f64):
    collider = tc.AnimatedMeshCollider(SHEET, waving)
    points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.1], [0.1, 0.0, 0.1]])
    sim = tc.Simulation(cloth_on_the_sheet(points), integrator="xpbd", dt=1e-3,
                        handles=[tc.Attachment([0, 1, 2, 3], collider, release=0.1)])
    sim.step(100)
    held = sim.positions()
    velocity = sim.velocities()
    sim.step(100)
    fall = sim.positions() - held - 0.1 * velocity
    report("drop below the surface's last motion after release (m)", fall[:, 1].mean(),
           "about -g t^2 / 2 = -0.049")
    assert fall[:, 1].mean() < -0.04


def test_bad_attachments_are_refused_by_name():
    collider = tc.AnimatedMeshCollider(SHEET, waving)
    cloth = cloth_on_the_sheet(SHEET.vertices[[0, 1, 6, 7]])
    flat = tc.AnimatedMeshCollider(tc.Mesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]),
                                           np.array([[0, 1, 2]])))
    cases = [(lambda: tc.Attachment([], collider), "Attachment.particles must be at least one"),
             (lambda: tc.Attachment([0], "sphere"), "Attachment.collider must be a collider"),
             (lambda: tc.Attachment([0], collider, release=-1), "Attachment.release must be"),
             (lambda: tc.Simulation(cloth, handles=[tc.Attachment([7], collider)]),
              "Attachment.particles must be particle indices in [0, 3], got [7]"),
             (lambda: tc.Attachment([0], flat).handle(cloth.particle_position),
              "the collider's triangle 0 at t = 0 s must be a triangle with an area")]
    for make, message in cases:
        with pytest.raises(ValueError) as caught:
            make()
        report("message", str(caught.value), message)
        assert message in str(caught.value)


SCENE = """
[simulation]
integrator = "xpbd"
dt = 0.005
duration = 0.5
[[bodies]]
type = "grid"
rows = 5
cols = 5
size = [0.4, 0.4]
plane = "xz"
origin = [-0.2, 0.205, -0.2]
[[bodies.attachments]]
particles = {{ centre = [0.0, 0.2, 0.0], radius = 0.12 }}
collider = {collider}
[[colliders]]
type = "plane"
[[colliders]]
type = "sphere"
radius = 0.2
path = {{ type = "keyframes", times = [0, 1], values = [[0, 0, 0], [0.5, 0, 0]] }}
"""


def test_scene_files_attach_a_ball_of_particles_to_a_collider_by_index(tmp_path, f64):
    path = tmp_path / "attached.toml"
    path.write_text(SCENE.format(collider=1))
    scene = load_scene(path)
    (attachment,) = scene.handles
    assert isinstance(attachment, tc.Attachment) and attachment.collider is scene.colliders[1]
    inside = np.flatnonzero(np.linalg.norm(scene.cloth.particle_position - (0, 0.2, 0), axis=1)
                            <= 0.12)
    np.testing.assert_array_equal(attachment.particles, inside)
    sim = scene.build()
    sim.step(100)
    moved = sim.positions()[inside] - scene.cloth.particle_position[inside]
    report("attached particles moved with the sphere (m)", moved[:, 0], 0.5 * sim.time)
    np.testing.assert_allclose(moved, np.tile([0.5 * sim.time, 0.0, 0.0], (len(inside), 1)),
                               atol=1e-12)
    for collider, message in (("2", r"collider must be an integer in \[0, 1\]"),
                              ('"ball"', r"collider must be an integer")):
        path.write_text(SCENE.format(collider=collider))
        with pytest.raises(SceneError, match=r"bodies\[0\]\.attachments\[0\]\." + message):
            load_scene(path)
