"""Animated (deforming) mesh colliders (animated_mesh.py, animated_contact.py) against
independent geometry: a breathing sphere checked with a winding number written here, a plate
swung through a particle faster than its thickness per step, a sliding plate carrying a sheet
by friction, and the same motion as samples and as a callable."""

import numpy as np
import pytest
from helpers import report, winding_numbers

import ti_cloth as tc

THICKNESS = 0.01
CENTRE = np.array([0.0, 0.0, 0.0])
RADIUS = 0.3
SPHERE = tc.sphere_mesh(RADIUS, CENTRE, subdivisions=3)


def breathing(t):
    """The sphere's vertices at time t: radius RADIUS (1 + 0.3 sin 2 pi t)."""
    return CENTRE + (SPHERE.vertices - CENTRE) * (1.0 + 0.3 * np.sin(2 * np.pi * t))


def falling_sheet(n=16):
    mesh = tc.grid_mesh(n, n, (1.0, 1.0), plane="xz", origin=(-0.5, 0.45, -0.5))
    return tc.Cloth(mesh, tc.Material(stretch=tc.SpringParams(2e3, 0.5),
                                      shear=tc.SpringParams(2e2, 0.05),
                                      bend=tc.SpringParams(5.0, 0.005)))


def frames_inside(collider, motion, seconds=0.5, fps=50):
    """Per frame, how many particles of a sheet dropped on `collider` lie inside the sphere
    as `motion` has it at the frame's time."""
    sim = tc.Simulation(falling_sheet(), integrator="symplectic_euler", dt=1e-4,
                        colliders=[collider])
    inside = []
    for _ in range(round(seconds * fps)):
        sim.step(round(1 / (fps * sim.dt)))
        w = winding_numbers(sim.positions(), motion(sim.time), SPHERE.triangles)
        inside.append(int((np.abs(w) > 0.5).sum()))
    return np.array(inside), sim


def test_a_breathing_sphere_keeps_a_falling_sheet_outside_in_every_frame(f64):
    """A sheet falls onto a sphere whose radius swings +-30 % once a second: in no frame is a
    particle inside the sphere as it is at the frame's time (the winding number above).
    The same sphere held at its rest shape swallows particles when the real one grows."""
    collider = tc.AnimatedMeshCollider(SPHERE, breathing, thickness=THICKNESS)
    inside, sim = frames_inside(collider, breathing)
    distance, _ = sim.collider_distance(sim.positions())
    report("particles inside per frame (max); nearest particle [m]", (inside.max(),
                                                                      distance.min()), 0)
    assert distance.min() < 2 * THICKNESS, "the sheet rests on the sphere at the end"
    assert inside.max() == 0
    still = tc.AnimatedMeshCollider(SPHERE, thickness=THICKNESS)
    swallowed, _ = frames_inside(still, breathing)
    assert swallowed.max() > 10


def test_a_plate_swung_through_a_particle_in_one_step_carries_it(f64):
    """A 1 m plate (two triangles) rises at 20 m/s, 2 cm a step, through a particle floating
    at rest 1 cm above it (gravity off; the thickness is 1 mm): continuous collision finds
    the crossing inside the step and the particle ends on the side it started, one thickness
    above the plate, moving with it. Tested at the particle's own moment of contact (a
    proximity test alone lets the plate pass: the particle ends 1 cm below it)."""
    square = np.array([[-0.5, 0.0, -0.5], [0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [-0.5, 0.0, 0.5]])
    plate = tc.Mesh(square, np.array([[0, 2, 1], [0, 3, 2]]))
    speed, dt, thickness = 20.0, 1e-3, 1e-3

    def rising(t):
        return square + [0.0, speed * t, 0.0]

    particle = tc.Cloth.from_particles([[0.1, 0.01, 0.2]], [0.01], np.zeros((0, 2), int))
    for collider in (tc.AnimatedMeshCollider(plate, rising, thickness=thickness),
                     tc.AnimatedMeshCollider(plate, np.stack([rising(k / 100) for k in range(3)]),
                                             fps=100, thickness=thickness)):
        sim = tc.Simulation(particle, integrator="symplectic_euler", dt=dt, gravity=(0, 0, 0),
                            colliders=[collider])
        sim.step(3)
        height = sim.positions()[0, 1] - speed * sim.time
        report("height above the plate after 3 steps [m]", height, thickness)
        assert height == pytest.approx(thickness, abs=1e-9)
        assert sim.velocities()[0, 1] == pytest.approx(speed, rel=1e-6)


def smooth_slide(distance, duration):
    """Displacement along x at time t of a ride that starts and ends at rest (cosine ramp)."""
    def x(t):
        s = min(max(t / duration, 0.0), 1.0)
        return distance * (s - np.sin(2 * np.pi * s) / (2 * np.pi))
    return x


@pytest.mark.parametrize("friction", [2.0, 0.0])
def test_a_sliding_plate_carries_a_sheet_resting_on_it_by_friction(f64, friction):
    """A sheet resting on a 2 m plate that slides 0.3 m sideways in 1 s (starting and ending
    at rest): with static friction 2 the sheet moves with the plate (within 10 %); without
    friction it stays where it was (within 10 % of the slide)."""
    square = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
    plate = tc.Mesh(square, np.array([[0, 2, 1], [0, 3, 2]]))
    slide = smooth_slide(0.3, 1.0)
    collider = tc.AnimatedMeshCollider(plate, lambda t: square + [slide(t), 0.0, 0.0],
                                       thickness=THICKNESS, static_friction=friction)
    mesh = tc.grid_mesh(8, 8, (0.4, 0.4), plane="xz", origin=(-0.2, THICKNESS, -0.2))
    sheet = tc.Cloth(mesh, tc.Material(stretch=tc.SpringParams(500.0, 0.2),
                                       shear=tc.SpringParams(50.0, 0.02),
                                       bend=tc.SpringParams(1.0, 0.001)))
    sim = tc.Simulation(sheet, integrator="symplectic_euler", dt=2e-4, colliders=[collider])
    start = sim.positions()[:, 0].mean()
    sim.step(round(1.2 / sim.dt))
    moved = sim.positions()[:, 0].mean() - start
    report(f"friction {friction}: the sheet moved [m]", moved, 0.3 if friction else 0.0)
    assert moved == pytest.approx(0.3 if friction else 0.0, abs=0.03)


def test_samples_and_a_callable_of_the_same_motion_agree_within_interpolation(f64):
    """The breathing sphere given as samples at 200 fps and as the function: 0.2 s into the
    sheet's contact (t = 0.32 s) they agree within what linear interpolation changes, the
    surface's position by A h^2 / 8 and its velocity by A h / 2 (A = 0.3 R (2 pi)^2, the
    largest radial acceleration, h = 1/200 s), which a particle carries for at most the
    contact's 0.2 s. The samples taken one frame late (a misread of the time) miss it."""
    fps, seconds, contact = 200, 0.32, 0.2
    acceleration = 0.3 * RADIUS * (2 * np.pi) ** 2
    h = 1.0 / fps
    bound = acceleration * h**2 / 8 + acceleration * h / 2 * contact
    times = np.arange(round(seconds * fps) + 2) / fps
    ends = []
    for collider in (tc.AnimatedMeshCollider(SPHERE, breathing, thickness=THICKNESS),
                     tc.AnimatedMeshCollider(SPHERE, np.stack([breathing(t) for t in times]),
                                             fps=fps, thickness=THICKNESS),
                     tc.AnimatedMeshCollider(SPHERE, np.stack([breathing(t - h) for t in times]),
                                             fps=fps, thickness=THICKNESS)):
        sim = tc.Simulation(falling_sheet(), integrator="symplectic_euler", dt=1e-4,
                            colliders=[collider])
        sim.step(round(seconds / sim.dt))
        ends.append(sim.positions())
    radius = RADIUS * (1 + 0.3 * np.sin(2 * np.pi * seconds))
    touching = np.abs(np.linalg.norm(ends[0] - CENTRE, axis=1) - radius) < 2 * THICKNESS
    gap, late = (np.abs(ends[0] - other).max() for other in ends[1:])
    report("largest difference [m]: samples, late samples; bound", (gap, late, bound), "")
    assert touching.sum() > 10, "the sheet is on the sphere"
    assert 0 < gap < bound < late
    assert touching.sum() > 10, "the sheet is on the sphere"
    assert 0 < gap < bound < late


def test_an_animated_collider_is_refused_with_the_field_named():
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.motion.shape"):
        tc.AnimatedMeshCollider(SPHERE, np.zeros((4, 3, 3)), fps=30)
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.fps"):
        tc.AnimatedMeshCollider(SPHERE, np.zeros((4, SPHERE.vertex_count, 3)))
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.fps"):
        tc.AnimatedMeshCollider(SPHERE, breathing, fps=30)
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.motion\(0.0\).shape"):
        tc.AnimatedMeshCollider(SPHERE, lambda t: np.zeros((3, 3)))
    bad = np.zeros((2, SPHERE.vertex_count, 3))
    bad[1, 5, 2] = np.nan
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.motion\[1, 5, 2\]"):
        tc.AnimatedMeshCollider(SPHERE, bad, fps=30)
    with pytest.raises(ValueError, match=r"AnimatedMeshCollider.path"):
        tc.AnimatedMeshCollider(SPHERE, path=lambda t: (t, 0, 0))


def test_candidate_lists_give_the_bits_of_a_traversal_at_every_step(f64, monkeypatch):
    """The sheet dropped on the breathing sphere with the lists as they are, and with room
    for one candidate (every list overflows, and its particle traverses the hierarchy at
    every step): the same positions to the bit."""
    from ti_cloth.contact import animated_contact
    runs = []
    for skin, listed in ((animated_contact.SKIN, animated_contact.LISTED),
                         (animated_contact.SKIN, 1)):
        monkeypatch.setattr(animated_contact, "SKIN", skin)
        monkeypatch.setattr(animated_contact, "LISTED", listed)
        collider = tc.AnimatedMeshCollider(SPHERE, breathing, thickness=THICKNESS)
        sim = tc.Simulation(falling_sheet(), integrator="symplectic_euler", dt=1e-4,
                            colliders=[collider])
        sim.step(2500)
        runs.append(sim.positions())
        distance, _ = sim.collider_distance(runs[-1])
        assert (distance < 2 * THICKNESS).sum() > 5, "the sheet lies on the sphere"
    np.testing.assert_array_equal(runs[0], runs[1])


def test_every_valid_candidate_list_holds_every_triangle_a_traversal_would_visit(f64):
    """After each step, for every particle whose list still holds (its epoch, within a skin
    of its anchor at the step's start and end), every triangle whose box meets the particle's
    path box is in the list: checked against all 1,280 triangles' boxes read back."""
    from ti_cloth.contact.animated_contact import SKIN
    sphere = tc.sphere_mesh(RADIUS, CENTRE, subdivisions=3)
    collider = tc.AnimatedMeshCollider(
        sphere, lambda t: CENTRE + (sphere.vertices - CENTRE) * (1.0 + 0.3 * np.sin(6 * t)),
        thickness=THICKNESS)
    sim = tc.Simulation(falling_sheet(), integrator="xpbd", dt=1 / 240, colliders=[collider])
    sim.step(60)
    bodies = sim.colliders.bodies
    checked = 0
    for _ in range(10):
        x0 = sim.positions()
        sim.step(1)
        x = sim.positions()
        lo, hi = bodies.lo.to_numpy(), bodies.hi.to_numpy()
        boxes = slice(0, bodies.triangle_total)
        count = bodies.listed_count.to_numpy()
        listed = bodies.listed.to_numpy().reshape(len(count), -1)
        anchor = bodies.anchor.to_numpy()
        current = bodies.listed_epoch.to_numpy() == bodies.epoch.to_numpy()[0]
        skin = SKIN * THICKNESS
        valid = (current & (count >= 0) & (np.linalg.norm(x0 - anchor, axis=1) <= skin)
                 & (np.linalg.norm(x - anchor, axis=1) <= skin))
        path_lo, path_hi = np.minimum(x0, x), np.maximum(x0, x)
        meets = ((lo[boxes][None] <= path_hi[:, None]).all(axis=2)
                 & (path_lo[:, None] <= hi[boxes][None]).all(axis=2))
        for i in np.flatnonzero(valid & meets.any(axis=1)):
            assert set(np.flatnonzero(meets[i])) <= set(listed[i, :count[i]].tolist()), i
            checked += 1
    report("valid lists checked against a traversal", checked, "> 100")
    assert checked > 100
