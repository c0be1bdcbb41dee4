"""Colliders against closed forms: a particle stops on the ground for every integrator,
Coulomb friction on a slope (sticks below tan a = mu, slides at g (sin a - mu cos a) above),
a cloth draped over a sphere, moving colliders, and no collision kernel in scenes without."""

import math

import numpy as np
import pytest
from helpers import compiled, forget_compiled, report

import ti_cloth as tc
from ti_cloth.contact.colliders import collision as colliders_module
from ti_cloth.state import copy_positions


def particle(height, velocity=(0.0, 0.0, 0.0)):
    return tc.Cloth.from_particles([[0.0, height, 0.0]], [0.01], np.zeros((0, 2), int))


@pytest.mark.parametrize("integrator, shape", [(name, "plane") for name in sorted(tc.INTEGRATORS)]
                         + [(name, "mesh") for name in ("symplectic_euler", "verlet", "xpbd")])
def test_falling_particle_stops_on_the_ground_with_restitution_zero(f64, integrator, shape):
    """On a plane exactly, for every integrator; on a slab mesh collider (top at y = 0) to the
    float32 rounding of its stored distances (1e-7 m here), for one integrator of each kind of
    history the response rewrites (velocities; Verlet's previous positions; position-based)."""
    thickness = 0.01
    ground = (tc.Plane(point=(0.0, 0.0, 0.0), thickness=thickness) if shape == "plane" else
              tc.MeshCollider(tc.box_mesh((-1.0, -0.1, -1.0), (1.0, 0.0, 1.0)),
                              thickness=thickness, resolution=16))
    exact = 1e-12 if shape == "plane" else 1e-7
    sim = tc.Simulation(particle(1.0), integrator=integrator, dt=1e-3, colliders=[ground])
    heights = []
    for _ in range(60):
        sim.step(25)
        heights.append(sim.positions()[0, 1])
    report("final height, velocity", (heights[-1], sim.velocities()[0].tolist()), (thickness, 0.0))
    assert min(heights) >= thickness - exact                    # never below, after any step
    assert abs(heights[-1] - thickness) < exact and np.abs(sim.velocities()).max() < 1e-9
    impact = math.sqrt(2 * (1.0 - thickness) / 9.81)            # s; then it stays put
    landed = [h for k, h in enumerate(heights) if (k + 1) * 0.025 > impact + 0.01]
    assert np.allclose(landed, thickness, atol=exact)


def slope_cloth(angle, mu, integrator="symplectic_euler", shape="plane"):
    """A 6 x 6, 0.5 m cloth lying on a plane through the origin tilted by `angle` about z; or
    (shape "mesh") on the top of an 8 m x 1 m x 2 m block mesh centred on the origin, turned by
    `angle` (its top's distance is linear a few cells deep, so the grid holds it exactly)."""
    normal = np.array([-math.sin(angle), math.cos(angle), 0.0])
    downhill = np.array([-math.cos(angle), -math.sin(angle), 0.0])
    across = np.array([0.0, 0.0, 1.0])
    mesh = tc.grid_mesh(6, 6, size=(0.5, 0.5), plane="xz", origin=(-0.25, 0.0, -0.25))
    u, w = mesh.vertices[:, 0], mesh.vertices[:, 2]
    thickness = 0.005
    surface = 0.5 if shape == "mesh" else 0.0                   # the block's half height
    x = np.outer(-u, downhill) + np.outer(w, across) + (surface + thickness) * normal
    material = tc.Material(density=0.2, stretch=tc.SpringParams(200.0, 0.2),
                           shear=tc.SpringParams(20.0, 0.02), bend=tc.SpringParams(1.0, 0.001))
    cloth = tc.Cloth(tc.Mesh(x, mesh.triangles, grid_shape=(6, 6)), material)
    if shape == "mesh":
        collider = tc.MeshCollider(tc.box_mesh((-4.0, -0.5, -1.0), (4.0, 0.5, 1.0)),
                                   rotation=lambda t: (0.0, 0.0, angle), resolution=64,
                                   thickness=thickness, static_friction=mu)
    else:
        collider = tc.Plane(normal=tuple(normal), thickness=thickness, static_friction=mu)
    dt = 1e-3 if integrator == "pbd" else 2e-4          # pbd has no step limit; the others do
    return tc.Simulation(cloth, integrator=integrator, dt=dt, colliders=[collider]), downhill


@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet", "pbd"])
def test_static_friction_holds_a_cloth_on_a_slope_below_tan_mu(f64, integrator):
    mu, angle = 0.5, math.atan(0.4)
    sim, downhill = slope_cloth(angle, mu, integrator)
    x0 = sim.positions()
    sim.step(int(round(2.0 / sim.dt)))                           # 2 s
    creep = np.abs((sim.positions() - x0) @ downhill).max()
    report("creep in 2 s [m]", creep, "< 1e-3")
    assert creep < 1e-3


@pytest.mark.parametrize("shape", ["plane", "mesh"])
def test_cloth_slides_down_a_slope_above_tan_mu_as_coulomb_says(f64, shape):
    """On a plane, and on a block mesh collider turned to the slope: the same law holds."""
    mu, angle = 0.5, math.atan(0.6)
    sim, downhill = slope_cloth(angle, mu, shape=shape)
    x0 = sim.positions()
    sim.step(5_000)                                              # 1 s
    slid = float(np.mean((sim.positions() - x0) @ downhill))
    expected = 0.5 * 9.81 * (math.sin(angle) - mu * math.cos(angle)) * 1.0 ** 2
    report("slide in 2 s [m]", slid, expected)
    # friction acts on the step's displacement, one step late at most: O(dt) relative error
    assert abs(slid - expected) < 0.02 * expected


@pytest.mark.slow
def test_cloth_drapes_over_a_sphere_and_stays(f64):
    n, radius, thickness = 12, 0.3, 0.01
    mesh = tc.grid_mesh(n, n, size=(1.0, 1.0), plane="xz", origin=(-0.5, 0.35, -0.5))
    material = tc.Material(density=0.2, stretch=tc.SpringParams(300.0, 0.3),
                           shear=tc.SpringParams(30.0, 0.03), bend=tc.SpringParams(0.5, 0.001))
    sphere = tc.Sphere(centre=(0.0, 0.0, 0.0), radius=radius, thickness=thickness,
                       static_friction=0.4)
    cloth = tc.Cloth(mesh, material)
    sim = tc.Simulation(cloth, dt=0.25 * tc.stable_dt(cloth, "symplectic_euler"), drag=1.0,
                        colliders=[sphere])
    steps = int(round(0.05 / sim.dt))
    closest = np.inf
    for _ in range(80):                                          # 4 s, checked every 50 ms
        sim.step(steps)
        closest = min(closest, np.linalg.norm(sim.positions(), axis=1).min())
    settled = sim.positions()
    sim.step(steps * 10)                                         # half a second more
    moved = np.linalg.norm(sim.positions() - settled, axis=1).max()
    top = sim.positions()[np.argmin(np.linalg.norm(mesh.vertices[:, [0, 2]], axis=1))]
    report("closest to centre, moved in last 0.5 s, top particle", (closest, moved, top.tolist()),
           (radius + thickness, "< 3 mm", "on the sphere"))
    assert closest >= radius + thickness - 1e-9
    assert moved < 3e-3                                               # at rest: 6 mm/s at most
    assert abs(np.linalg.norm(top) - (radius + thickness)) < 2e-3     # resting on it
    assert sim.positions()[:, 1].min() < -0.1                         # the skirt hangs down


def test_particle_rides_a_moving_platform(f64):
    # a box rising at 0.5 m/s carries a particle resting on it, which moves with it
    box = tc.Box(lo=(-1.0, -1.0, -1.0), hi=(1.0, 0.0, 1.0), static_friction=1.0,
                 path=lambda t: (0.3 * t, 0.5 * t, 0.0))
    sim = tc.Simulation(particle(0.0), dt=1e-3, colliders=[box])
    sim.step(1000)
    report("position after 1 s", sim.positions()[0].tolist(), [0.3, 0.5, 0.0])
    assert np.allclose(sim.positions()[0], [0.3, 0.5, 0.0], atol=2e-5)
    assert np.allclose(sim.velocities()[0], [0.3, 0.5, 0.0], atol=1e-6)
    # what a renderer draws: the box where its path has it now, at its size
    placed, = sim.collider_shapes()
    report("box drawn at t = 1 s (lo, hi)", (placed.lo, placed.hi), "moved by (0.3, 0.5, 0)")
    np.testing.assert_allclose(placed.lo, np.add(box.lo, box.path(sim.time)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(placed.hi, np.add(box.hi, box.path(sim.time)), rtol=0, atol=1e-15)
    assert placed.path is None and placed.static_friction == box.static_friction


def test_colliders_are_placed_by_their_paths():
    still = tc.Plane(point=(0.0, -1.0, 0.0))
    assert still.placed(2.0) is still
    moving = [tc.Sphere(centre=(1, 2, 3), radius=0.5, path=lambda t: (t, 0, 0)),
              tc.Capsule(a=(0, 0, 0), b=(1, 0, 0), radius=0.1, path=lambda t: (0, t, 0)),
              tc.Plane(point=(0, 0, 0), normal=(0, 0, 1), path=lambda t: (0, 0, 2 * t))]
    sphere, capsule, plane = (c.placed(0.5) for c in moving)
    assert sphere.centre == (1.5, 2.0, 3.0) and sphere.radius == 0.5
    assert capsule.a == (0.0, 0.5, 0.0) and capsule.b == (1.0, 0.5, 0.0)
    assert plane.point == (0.0, 0.0, 1.0) and plane.normal == (0.0, 0.0, 1.0)


@pytest.mark.parametrize("shape, inside, surface", [
    (tc.Sphere(centre=(0, 0, 0), radius=0.5), (0.1, 0.2, 0.0), lambda x: np.linalg.norm(x) - 0.5),
    (tc.Box(lo=(-1, -1, -1), hi=(1, 0, 1)), (0.2, -0.1, 0.3), lambda x: x[1]),
    (tc.Capsule(a=(-1, 0, 0), b=(1, 0, 0), radius=0.3), (0.5, 0.1, 0.1),
     lambda x: np.linalg.norm(x[1:]) - 0.3),
])
def test_a_particle_started_inside_is_pushed_to_the_surface(f64, shape, inside, surface):
    body = tc.Cloth.from_particles([inside], [0.01], np.zeros((0, 2), int))
    sim = tc.Simulation(body, dt=1e-3, gravity=(0.0, 0.0, 0.0), colliders=[shape])
    sim.step(1)
    x = sim.positions()[0]
    report("distance to surface after one step", surface(x), 0.0)
    assert abs(surface(x)) < 1e-12


def test_scene_without_colliders_compiles_no_collision_kernel(f64):
    forget_compiled(colliders_module.resolve, copy_positions)
    sim = tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=1e-4)
    sim.step(3)
    assert not compiled(colliders_module.resolve)
    assert not compiled(copy_positions)
    grounded = tc.Simulation(particle(1.0), dt=1e-3, colliders=[tc.Plane()])
    grounded.step(1, plan="per stage")      # the collision stage's own kernel
    assert compiled(colliders_module.resolve)


@pytest.mark.parametrize("make, field", [
    (lambda: tc.Sphere(radius=-1.0), "Sphere.radius"),
    (lambda: tc.Plane(normal=(0, 0, 0)), "Plane.normal"),
    (lambda: tc.Box(lo=(0, 0, 0), hi=(1, 0, 1)), "Box.hi"),
    (lambda: tc.Capsule(thickness=-0.1), "Capsule.thickness"),
    (lambda: tc.Plane(static_friction=float("nan")), "Plane.static_friction"),
])
def test_colliders_reject_bad_input_by_name(make, field):
    with pytest.raises(ValueError, match=field):
        make()
