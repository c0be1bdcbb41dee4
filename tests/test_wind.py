"""Per-triangle aerodynamics against the flat-plate formulas, an independent numpy evaluation
of the wind field, and a flag in wind."""

import numpy as np
import pytest
from helpers import compiled, forget_compiled, report

import ti_cloth as tc
from ti_cloth.physics import wind as wind_module
from ti_cloth.physics.forces import ForceSettings, compute_forces
from ti_cloth.physics.wind import WindField

RHO = 1.2


def triangle(vertices):
    return tc.Cloth(tc.Mesh(vertices, [[0, 1, 2]]), tc.Material())


def wind_forces_at(cloth, wind, x=None, v=None):
    """A function t -> per-particle aerodynamic force [N] (gravity off) at positions x and
    velocities v (its kernels compiled once)."""
    model = tc.Model(cloth)
    state = model.state()
    if x is not None:
        state.particle_position.from_numpy(x)
    if v is not None:
        state.particle_velocity.from_numpy(v)
    field = WindField(wind, cloth)
    forces = ForceSettings(gravity=(0.0, 0.0, 0.0), wind=field)

    def at(t):
        compute_forces(model, state, forces, time=t)
        return state.particle_force.to_numpy()
    return at


def wind_forces(cloth, wind, x=None, v=None, t=0.0):
    """Per-particle aerodynamic force [N] (gravity off) at positions x, velocities v, time t."""
    return wind_forces_at(cloth, wind, x, v)(t)


# A right triangle in the xy plane with legs 1 m and 0.5 m: area 0.25 m^2, normal +z.
FLAT = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.5, 0.0]]
AREA = 0.25


def test_face_on_wind_gives_drag_only_along_the_flow(f64):
    speed, cd, cf = 4.0, 1.3, 0.05
    wind = tc.Wind(velocity=(0, 0, -speed), drag_coefficient=cd, lift_coefficient=0.8,
                   friction_coefficient=cf)
    f = wind_forces(triangle(FLAT), wind)
    expected = 0.5 * RHO * speed ** 2 * AREA * (cd + cf) / 3
    report("per-corner force", f[0], (0, 0, -expected))
    np.testing.assert_allclose(f, np.tile([0, 0, -expected], (3, 1)), atol=1e-12)


def test_edge_on_triangle_feels_only_friction_drag_and_no_lift(f64):
    speed, cf = 6.0, 0.05
    wind = tc.Wind(velocity=(speed, 0, 0), drag_coefficient=1.0, lift_coefficient=2.0,
                   friction_coefficient=cf)
    f = wind_forces(triangle(FLAT), wind).sum(axis=0)
    drag = 0.5 * RHO * speed ** 2 * AREA * cf
    report("total force (edge-on)", f, (drag, 0, 0))
    assert abs(f[0] - drag) < 1e-12
    assert np.abs(f[1:]).max() < 1e-14, "an edge-on plate must feel no lift"


@pytest.mark.parametrize("angle_deg", [30.0, 45.0, 70.0])
def test_inclined_triangle_drag_and_lift_match_the_flat_plate_model(f64, angle_deg):
    """Flow in the xz plane at angle a from the plate (xy plane): c = sin a; the lift is
    perpendicular to the flow with magnitude q C_lift sin a cos a, pushing the plate the way
    the flow crosses it."""
    speed, cd, cl, cf = 5.0, 1.1, 0.9, 0.02
    a = np.radians(angle_deg)
    flow = np.array([np.cos(a), 0.0, -np.sin(a)])
    wind = tc.Wind(velocity=speed * flow, drag_coefficient=cd, lift_coefficient=cl,
                   friction_coefficient=cf)
    f = wind_forces(triangle(FLAT), wind).sum(axis=0)
    q = 0.5 * RHO * speed ** 2 * AREA
    drag, lift = f @ flow, f - (f @ flow) * flow
    lift_direction = np.array([np.sin(a), 0.0, np.cos(a)]) * -1   # across the flow, towards -z
    report("drag, lift", (drag, lift), (q * (cd * np.sin(a) + cf), q * cl * np.sin(a) * np.cos(a)))
    assert abs(drag - q * (cd * np.sin(a) + cf)) < 1e-12
    np.testing.assert_allclose(lift, q * cl * np.sin(a) * np.cos(a) * lift_direction, atol=1e-12)


def test_a_triangle_moving_through_still_air_is_braked(f64):
    v = np.tile([0.0, 0.0, 2.0], (3, 1))
    f = wind_forces(triangle(FLAT), tc.Wind(), v=v).sum(axis=0)
    expected = -0.5 * RHO * 4.0 * AREA * (1.0 + 0.02)
    report("force on a plate moving at 2 m/s", f, (0, 0, expected))
    np.testing.assert_allclose(f, [0, 0, expected], atol=1e-12)


def reference_forces(cloth, wind, x, v, t):
    """The module doc's formulas written out in numpy, triangle by triangle."""
    wave, direction, phase = wind.turbulence_modes()
    f = np.zeros_like(x)
    for tri in cloth.mesh.triangles:
        p = x[tri]
        centre = p.mean(axis=0) - np.asarray(wind.velocity) * t
        turbulent = (direction * np.sin(wave @ centre + phase)[:, None]).sum(axis=0)
        air = np.asarray(wind.velocity) * (1 + wind.gust * np.sin(2 * np.pi * t / wind.gust_period))
        u = air + wind.turbulence * np.sqrt(2 / len(phase)) * turbulent - v[tri].mean(axis=0)
        normal = 0.5 * np.cross(p[1] - p[0], p[2] - p[0])
        area = np.linalg.norm(normal)
        n, speed = normal / area, np.linalg.norm(u)
        cos = n @ u / speed
        q = 0.5 * wind.air_density * speed ** 2 * area
        force = q * ((wind.drag_coefficient * abs(cos) + wind.friction_coefficient) * u / speed
                     + wind.lift_coefficient * cos * (n - cos * u / speed))
        f[tri] += force / 3
    return f


def test_gusting_turbulent_wind_on_a_moving_cloth_matches_a_numpy_evaluation(f64):
    no_springs = tc.SpringParams(0.0)
    cloth = tc.Cloth(tc.grid_mesh(5, 4, size=(0.9, 0.7)),
                     tc.Material(stretch=no_springs, shear=no_springs, bend=no_springs))
    rng = np.random.default_rng(3)
    x = cloth.particle_position + rng.normal(scale=0.05, size=(cloth.particle_count, 3))
    v = rng.normal(scale=0.5, size=x.shape)
    wind = tc.Wind(velocity=(3.0, 0.5, -1.0), gust=0.4, gust_period=1.5, turbulence=1.2,
                   turbulence_scale=0.6, seed=7)
    forces_at = wind_forces_at(cloth, wind, x, v)
    for t in (0.0, 0.37, 1.1):
        got = forces_at(t)
        expected = reference_forces(cloth, wind, x, v, t)
        err = np.abs(got - expected).max()
        report(f"max force difference at t={t}", err, f"< 1e-12 (|f| max {np.abs(expected).max():.3g})")
        assert err < 1e-12


def test_turbulence_has_the_requested_rms_and_no_divergence():
    """Over many points the fluctuation averages to ~0 with RMS speed = turbulence, and each
    mode's direction is perpendicular to its wave vector (divergence-free)."""
    wind = tc.Wind(turbulence=2.0, turbulence_scale=0.5, seed=1)
    wave, direction, phase = wind.turbulence_modes()
    assert np.abs(np.sum(wave * direction, axis=1)).max() < 1e-12
    points = np.random.default_rng(0).uniform(-20, 20, size=(200_000, 3))
    u = 2.0 * np.sqrt(2 / len(phase)) * (np.sin(points @ wave.T + phase) @ direction)
    rms = np.sqrt(np.mean(np.sum(u * u, axis=1)))
    report("turbulence RMS speed", rms, "2.0 within 2 %")
    assert abs(rms - 2.0) < 0.04


def banner_displacement(speed):
    """Mean displacement [m] of a banner hung from a horizontal pole (top row pinned) in wind
    blowing across it (+z), averaged over the last 0.4 s of 1.2 s."""
    mesh = tc.grid_mesh(7, 9, size=(0.6, 0.45), plane="xy")
    material = tc.Material(density=0.15, stretch=tc.SpringParams(300.0, 0.3),
                           shear=tc.SpringParams(30.0, 0.03), bend=tc.SpringParams(0.5, 0.001))
    cloth = tc.Cloth(mesh, material, pinned=range(6 * 9, 7 * 9))
    wind = tc.Wind(velocity=(0.0, 0.0, speed), turbulence=0.1 * speed, turbulence_scale=0.4)
    sim = tc.Simulation(cloth, dt=2.5e-4, wind=wind)
    samples = []
    while sim.time < 1.2 - 1e-9:
        sim.step(200)
        if sim.time > 0.8 + 1e-9:
            samples.append(sim.positions().mean(axis=0) - cloth.particle_position.mean(axis=0))
    return np.mean(samples, axis=0)


@pytest.mark.slow
def test_banner_moves_downwind_more_in_stronger_wind(f32):
    """The mean displacement points downwind (its largest component is +z, the wind's
    direction) and grows with the wind speed; in still air the banner only sags (no z)."""
    still = banner_displacement(0.0)
    moved = [banner_displacement(s) for s in (0.5, 1.0, 2.0)]
    downwind = [d[2] for d in moved]
    report("mean displacement in still air [m]", still, "z = 0")
    report("mean downwind displacement at 0.5, 1, 2 m/s [m]", downwind, "increasing, > 0")
    assert abs(still[2]) < 1e-6
    assert 0 < downwind[0] < downwind[1] < downwind[2]
    assert all(d[2] > np.abs(d[:2]).max() for d in moved)


def test_scene_without_wind_compiles_no_wind_kernel(f64):
    forget_compiled(wind_module.wind_on_triangle)
    tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=1e-4).step(3)
    assert not compiled(wind_module.wind_on_triangle)
    windy = tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=1e-4,
                          wind=tc.Wind(velocity=(1, 0, 0)))
    windy.step(1)
    assert compiled(wind_module.wind_on_triangle)


@pytest.mark.parametrize("kwargs, field", [
    (dict(velocity=(1, 0)), "Wind.velocity"), (dict(gust_period=0.0), "Wind.gust_period"),
    (dict(turbulence=-1.0), "Wind.turbulence"), (dict(air_density=float("nan")), "Wind.air_density"),
    (dict(lift_coefficient=-0.1), "Wind.lift_coefficient"),
])
def test_wind_rejects_bad_input_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        tc.Wind(**kwargs)


def test_wind_needs_triangles(f64):
    string = tc.Cloth.from_particles([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]])
    with pytest.raises(ValueError, match="triangles"):
        tc.Simulation(string, wind=tc.Wind(velocity=(1, 0, 0)))
