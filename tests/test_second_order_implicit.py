"""Implicit midpoint and TR-BDF2 (integrators/implicit_midpoint.py, tr_bdf2.py; their Newton
solve, newton.py): on a spring chain's normal mode each follows its own linear map, R(i w h)
per step (the midpoint keeps every amplitude and turns by 2 atan(w h / 2); TR-BDF2 damps the
modes it cannot resolve), at steps far beyond the explicit limit, and both are order 2
against the chain's exact motion; energy kept on linear springs and bounded on a nonlinear
pendulum where implicit Euler loses it; the equilibrium implicit Euler settles to; loose
solves at a small step within their tolerance; their options checked."""

import numpy as np
import pytest

import ti_cloth as tc

K, MASS, N = 100.0, 0.01, 9          # spring constant [N/m], particle mass [kg], free particles


def chain_mode(amplitude=0.01, mode=1):
    """A string of N free particles between two fixed ones, displaced along its length in
    normal mode `mode`: (body, displaced positions, the mode's shape, w [rad/s])."""
    body = tc.string(N + 2, 1.0, mass=MASS * (N + 2), stretch=tc.SpringParams(K, 0.0),
                     fixed="both", end_mass="full")
    j = np.arange(N + 2)
    shape = np.sin(j * mode * np.pi / (N + 1))          # 0 at both fixed ends
    x = body.particle_position.copy()
    x[:, 0] += amplitude * shape
    w = 2.0 * np.sqrt(K / MASS) * np.sin(mode * np.pi / (2 * (N + 1)))
    return body, x, shape, w


def run_chain(integrator, dt, steps, amplitude=0.01):
    body, x, shape, w = chain_mode(amplitude)
    sim = tc.Simulation(body, integrator=integrator, dt=dt, gravity=(0.0, 0.0, 0.0))
    sim.set_positions(x)
    sim.step(steps)
    return sim, (sim.positions()[:, 0] - body.particle_position[:, 0]), shape, w


def tight(name="implicit_midpoint"):
    cls = {"implicit_midpoint": tc.ImplicitMidpoint, "tr_bdf2": tc.TRBDF2}[name]
    return cls(tolerance=1e-14, cg_tolerance=1e-13)


def stability(name, z):
    """The method's map of one step on y' = z y / h (its stability function R(z))."""
    if name == "implicit_midpoint":
        return (1 + z / 2) / (1 - z / 2)
    if name == "implicit_euler":
        return 1 / (1 - z)
    gamma = 2 - np.sqrt(2)                      # TR-BDF2: trapezoid over gamma h, then BDF2
    a, b = 1 / (gamma * (2 - gamma)), (1 - gamma) ** 2 / (gamma * (2 - gamma))
    trapezoid = (1 + gamma * z / 2) / (1 - gamma * z / 2)
    return (a * trapezoid - b) / (1 - gamma * z / 2)


@pytest.mark.parametrize("name", ["implicit_midpoint", "tr_bdf2"])
def test_a_chain_mode_follows_the_methods_own_linear_map(f64, name):
    """The chain is linear along its length, so a step multiplies the mode's complex
    amplitude by R(i w h): implicit midpoint's |R| = 1 with phase 2 atan(w h / 2) (no
    numerical damping), TR-BDF2's |R| < 1 tending to 0 (L-stable). At w h = 4 (twice the
    explicit limit) the displacement after 50 steps is amplitude x shape x Re R^50, to the
    Newton tolerance; implicit Euler's R = 1 / (1 - z) leaves 1e-18 of it."""
    _, _, _, w = chain_mode()
    dt, steps, amplitude = 4.0 / w, 50, 0.01
    _, u, shape, _ = run_chain(tight(name), dt, steps, amplitude)
    expected = amplitude * shape * (stability(name, 4.0j) ** steps).real
    assert np.abs(expected).max() > 1e-5 * amplitude, "the mode is well away from 0"
    np.testing.assert_allclose(u, expected, atol=1e-9 * np.abs(expected).max() + 1e-13)
    if name == "implicit_midpoint":
        assert abs(abs(stability(name, 4.0j)) - 1) < 1e-15
        _, euler, _, _ = run_chain(tc.ImplicitEuler(tolerance=1e-12), dt, steps, amplitude)
        assert np.abs(euler).max() < 1e-6 * amplitude
        assert np.abs(stability("implicit_euler", 4.0j) ** steps) < 1e-6


@pytest.mark.parametrize("name", ["implicit_midpoint", "tr_bdf2"])
def test_order_two_against_the_chains_exact_motion(f64, name):
    """Error at t = 2.25 periods (the mode passing 0, where a phase error shows at first
    order) against amplitude x shape x cos(w t) at w h = 0.4, 0.2, 0.1: log2 ratios of 2
    within 0.1 (the next terms of the phase are (w h)^2 = 0.16 of the first at the coarsest)."""
    _, _, _, w = chain_mode()
    t, amplitude = 2.25 * 2 * np.pi / w, 0.01
    errors = []
    for wh in (0.4, 0.2, 0.1):
        steps = round(t * w / wh)
        _, u, shape, _ = run_chain(tight(name), t / steps, steps, amplitude)
        errors.append(np.abs(u - amplitude * shape * np.cos(w * t)).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.1), (errors, orders)


def test_energy_is_kept_on_linear_springs_and_bounded_on_a_swinging_pendulum(f64):
    """The chain's energy is quadratic, an invariant implicit midpoint keeps exactly (Hairer,
    Lubich & Wanner VI.3: to the Newton tolerance over 200 steps at w h = 4). A stiff spring
    pendulum swinging under gravity is not linear: its energy oscillates with the step but
    does not grow, over 20 swings; implicit Euler at the same step loses most of it."""
    _, _, _, w = chain_mode()
    sim, _, _, _ = run_chain(tight(), 4.0 / w, 0)
    e0 = sim.energy()["total"]
    sim.step(200)
    assert abs(sim.energy()["total"] / e0 - 1.0) < 1e-9

    def pendulum(integrator):
        body = tc.string(2, 0.5, mass=0.2, stretch=tc.SpringParams(2e3, 0.0), fixed="start",
                         end_mass="full")
        sim = tc.Simulation(body, integrator=integrator, dt=0.01)
        x = body.particle_position.copy()
        x[1] = [0.5 * np.sin(1.0), -0.5 * np.cos(1.0), 0.0]
        sim.set_positions(x)
        energies = [sim.energy()["total"]]
        for _ in range(30):             # 30 s: about 20 swings of 1.4 s
            sim.step(100)
            energies.append(sim.energy()["total"])
        return np.array(energies)

    kept = pendulum(tight())
    lost = pendulum(tc.ImplicitEuler(tolerance=1e-12))
    swing = kept[0] - kept.min()
    assert kept.max() <= kept[0] + 0.02 * abs(kept[0]), kept
    assert lost[-1] < kept[0] - 20 * max(swing, 1e-12), (lost, kept)


@pytest.mark.parametrize("body", ["springs", "fabric"])
def test_it_settles_where_implicit_euler_does(f64, body):
    """With drag they come to rest where the forces balance, which no integrator changes:
    the same positions to the solvers' tolerances (1e-7 m), after 12 s of 1/60 s steps. The
    sheet hangs in its own plane, which has one equilibrium (hung flat, a small sheet sags
    into a fold up or down, mirror images either integrator may take).
    TR-BDF2 comes to rest; implicit midpoint's stiffest modes (w h ~ 100 here) ring on at
    |R| = 1 - O(drag / (w^2 h)), about its rest but not to rest (module doc)."""
    mesh = tc.grid_mesh(4, 4, size=(0.3, 0.3), plane="xy")      # hanging in its plane: one
    top = np.flatnonzero(mesh.vertices[:, 1] == mesh.vertices[:, 1].max())   # equilibrium
    material = tc.Fabric.preset("denim", bending_curve=None) if body == "fabric" else tc.Material()
    cloth = tc.Cloth(mesh, material, pinned=[top[0], top[-1]])
    rest = {}
    for name, integrator in (("implicit_euler", tc.ImplicitEuler(tolerance=1e-12, max_iterations=2000)),
                             ("tr_bdf2", tight("tr_bdf2")),
                             ("implicit_midpoint", tight())):
        sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 60, drag=4.0)
        sim.step(720)
        rest[name] = (sim.positions(), np.abs(sim.velocities()).max())
    assert np.abs(rest["implicit_euler"][0] - cloth.particle_position).max() > 1e-5, "it sags"
    assert rest["implicit_euler"][1] < 1e-6 and rest["tr_bdf2"][1] < 1e-6
    for name in ("tr_bdf2", "implicit_midpoint"):
        np.testing.assert_allclose(rest[name][0], rest["implicit_euler"][0], atol=1e-7, err_msg=name)


def test_loose_solves_at_a_small_step_stay_within_their_tolerance(f32):
    """Newton's update test waits for a second iteration (newton.LEAST_NEWTON): the first
    update, from the predictor, is small at a small step however inexact its CG. A 12² denim
    sheet at 1/960 s with the loose preset (Newton to 0.1 mm, CG to a tenth) stays within
    that 0.1 mm of the default solves over 0.15 s (0.03 mm; stopping after one iteration it
    drifts 0.68 mm away, 120 mm at 32² over 0.3 s)."""
    n = 12
    cloth = tc.Cloth(tc.grid_mesh(n, n, size=(0.5, 0.5), plane="xz"),
                     tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=1e-4),
                     pinned=[0, n - 1])
    loose = tc.ImplicitMidpoint.presets["loose"]
    sims = [tc.Simulation(cloth, dt=1 / 960, integrator=tc.ImplicitMidpoint(**options))
            for options in ({}, loose)]
    for sim in sims:
        sim.step(144)
    apart = np.linalg.norm(sims[0].positions() - sims[1].positions(), axis=1).max()
    assert sims[1].integrator.last_newton >= 2
    assert apart <= loose["tolerance"], apart


@pytest.mark.parametrize("cls", [tc.ImplicitMidpoint, tc.TRBDF2])
@pytest.mark.parametrize("option, value", [("tolerance", 0.0), ("tolerance", float("nan")),
                                           ("most_newton", 0), ("cg_tolerance", 1.0),
                                           ("most_cg", -3), ("preconditioner", "ilu"),
                                           ("aggregate_size", 0), ("aggregate_size", 2.5)])
def test_bad_options_are_refused_by_name(cls, option, value):
    with pytest.raises(ValueError, match=f"{cls.__name__}.{option}"):
        cls(**{option: value})


@pytest.mark.parametrize("option, value", [("preconditioner", "multigrid"),
                                           ("aggregate_size", -1)])
def test_implicit_euler_refuses_a_bad_preconditioner_by_name(option, value):
    with pytest.raises(ValueError, match=f"ImplicitEuler.{option}.*{value}"):
        tc.ImplicitEuler(**{option: value})
