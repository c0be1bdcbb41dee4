"""Each integrator against its discrete closed form: free fall, oscillators, equilibrium."""

import math

import numpy as np
import pytest
from helpers import report, stretched_energy_ratios

import ti_cloth as tc

FORCE_BASED = ["explicit_euler", "symplectic_euler", "verlet", "implicit_euler", "rk4"]
ALL = FORCE_BASED + ["pbd", "xpbd"]


def spring_pair(masses, k, kd=0.0, rest=1.0, pinned=(), damping="axial"):
    material = tc.Material(stretch=tc.SpringParams(k, kd), damping=damping)
    return tc.Cloth.from_particles([[0, 0, 0], [rest, 0, 0]], masses, [[0, 1]], material, pinned=pinned)


@pytest.mark.parametrize("integrator", ALL)
def test_free_fall_matches_discrete_closed_form(f64, integrator):
    cloth = tc.Cloth(tc.grid_mesh(6, 5, size=(0.5, 0.6)), tc.Material())
    h, n, g = 5e-5, 400, np.array([0.0, -9.81, 0.0])
    v0 = np.array([0.3, 0.5, -0.2])
    spec = tc.ImplicitEuler(tolerance=1e-12) if integrator == "implicit_euler" else integrator
    sim = tc.Simulation(cloth, integrator=spec, dt=h, gravity=g)
    assert h < sim.stable_dt(), "rounding noise in the springs must not grow"
    sim.set_velocities(np.tile(v0, (cloth.particle_count, 1)))
    sim.step(n)
    # explicit: sum_{k<n} h v_k -> n(n-1)/2; symplectic, implicit Euler and the XPBD prediction
    # (springs at rest move rigidly, so K v = 0 and no constraint acts): sum_{k<=n} -> n(n+1)/2;
    # Verlet/PBD with the second-order start and rk4: exact parabola n^2/2
    late = n * (n + 1) / 2
    factor = {"explicit_euler": n * (n - 1) / 2, "symplectic_euler": late, "implicit_euler": late,
              "xpbd": late}.get(integrator, n * n / 2)
    expected = cloth.particle_position + v0 * n * h + g * h * h * factor
    err = np.abs(sim.positions() - expected).max()
    report(f"{integrator} free-fall error [m]", err, "< 1e-10 (f64 rounding; CG solved to 1e-12)")
    assert err < 1e-10


@pytest.mark.parametrize("integrator", FORCE_BASED)
def test_two_particle_period(f64, integrator):
    m1, m2, k, h = 1.0, 2.0, 40.0, 1e-3
    mu = m1 * m2 / (m1 + m2)
    omega = math.sqrt(k / mu)
    period = 2 * math.pi * math.sqrt(mu / k)
    sim = tc.Simulation(spring_pair([m1, m2], k), integrator=integrator, dt=h, gravity=(0, 0, 0))
    x = sim.positions()
    x[1, 0] += 0.1
    sim.set_positions(x)
    stretch = []
    for _ in range(int(5.2 * period / h)):
        sim.step(1)
        p = sim.positions()
        stretch.append(np.linalg.norm(p[1] - p[0]) - 1.0)
    s = np.array(stretch)
    t = h * np.arange(1, len(s) + 1)
    up = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))          # upward zero crossings
    crossings = t[up] + h * (-s[up]) / (s[up + 1] - s[up])
    measured = np.mean(np.diff(crossings))
    # phase error per step of these first/second-order maps is O((w h)^3): relative period
    # error (w h)^2 / 24 (symplectic, Verlet) or (w h)^2 / 3 (explicit and implicit Euler:
    # phase atan(w h) per step), less for rk4; allow (w h)^2.
    tol = (omega * h) ** 2
    report(f"{integrator} period [s]", measured, f"{period} +- {tol * period:.2e}")
    assert len(crossings) >= 4
    assert abs(measured / period - 1) < tol


def test_explicit_euler_energy_grows_by_exactly_one_plus_h2w2(f64):
    m, k, h = 0.5, 50.0, 0.01
    w2 = k / m
    sim = tc.Simulation(spring_pair([0.0, m], k, pinned=[0]), integrator="explicit_euler", dt=h,
                        gravity=(0, 0, 0))
    ratios = stretched_energy_ratios(sim)
    report("E_{n+1}/E_n", (ratios.min(), ratios.max()), 1 + h * h * w2)
    np.testing.assert_allclose(ratios, 1 + h * h * w2, rtol=1e-11)


def test_symplectic_euler_energy_stays_bounded(f64):
    m, k, h = 0.5, 50.0, 0.02
    w = math.sqrt(k / m)
    sim = tc.Simulation(spring_pair([0.0, m], k, pinned=[0]), integrator="symplectic_euler", dt=h,
                        gravity=(0, 0, 0))
    x = sim.positions()
    x[1, 0] += 0.1
    sim.set_positions(x)
    s0 = 0.1
    e0 = sim.energy()["total"]
    energy, invariant = [], []
    for _ in range(400):
        sim.step(5)
        p, v = sim.positions()[1, 0] - 1.0, sim.velocities()[1, 0]
        energy.append(sim.energy()["total"])
        invariant.append(v * v + w * w * p * p - h * w * w * p * v)
    # the map conserves Q = v^2 + w^2 s^2 - h w^2 s v exactly, which bounds the energy:
    # E/E0 in [(1 - hw/2)/(1 + hw/2), (1 + hw/2)/(1 - hw/2)]
    q0 = w * w * s0 * s0
    np.testing.assert_allclose(invariant, q0, rtol=1e-10)
    a = h * w / 2
    ratio = np.array(energy) / e0
    report("E/E0 range", (ratio.min(), ratio.max()), ((1 - a) / (1 + a), (1 + a) / (1 - a)))
    assert (1 - a) / (1 + a) - 1e-12 <= ratio.min() and ratio.max() <= (1 + a) / (1 - a) + 1e-12


@pytest.mark.parametrize("integrator", FORCE_BASED + ["xpbd"])
def test_hanging_mass_settles_at_mg_over_k(f64, integrator):
    m, k, kd, g = 0.2, 100.0, 2.0, 9.81
    cloth = tc.Cloth.from_particles([[0, 0, 0], [0, -1.0, 0]], [0.0, m], [[0, 1]],
                                    tc.Material(stretch=tc.SpringParams(k, kd)), pinned=[0])
    sim = tc.Simulation(cloth, integrator=integrator, dt=1e-3, gravity=(0, -g, 0))
    sim.step(6000)  # amplitude decays as exp(-kd t / 2m) = exp(-30) over 6 s
    stretch = -sim.positions()[1, 1] - 1.0
    report(f"{integrator} static stretch [m]", stretch, m * g / k)
    assert abs(stretch - m * g / k) < 1e-9


def test_verlet_damping_factor_is_the_lecture_1_99_0_99(f64):
    cloth = tc.Cloth.from_particles([[0, 0, 0]], [1.0], np.zeros((0, 2), int))
    h, n, v0 = 0.01, 50, np.array([1.0, 2.0, 0.0])
    sim = tc.Simulation(cloth, integrator=tc.Verlet(damping=0.01), dt=h, gravity=(0, 0, 0))
    sim.set_velocities(v0[None])
    sim.step(n)
    # x_{n+1} = 1.99 x_n - 0.99 x_{n-1}: each displacement is 0.99 times the previous one
    expected = h * v0 * sum(0.99 ** j for j in range(1, n + 1))
    np.testing.assert_allclose(sim.positions()[0], expected, rtol=1e-12)


def test_pbd_relaxation_is_mass_weighted_projection(f64):
    masses = [1.0, 3.0]
    cloth = spring_pair(masses, 1.0)
    sim = tc.Simulation(cloth, integrator=tc.PBD(iterations=1), dt=1e-3, gravity=(0, 0, 0))
    x = np.array([[0.0, 0.0, 0.0], [1.2, 0.9, 0.0]])  # length 1.5, rest 1
    sim.set_positions(x)
    sim.step(1)
    p = sim.positions()
    com = lambda y: (masses[0] * y[0] + masses[1] * y[1]) / sum(masses)
    report("length after one pass", np.linalg.norm(p[1] - p[0]), 1.0)
    assert np.linalg.norm(p[1] - p[0]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(com(p), com(x), atol=1e-12)
    # the lighter particle moves 3x as far (w_p / (w_p + w_q) = 3/4)
    np.testing.assert_allclose(np.linalg.norm(p[0] - x[0]) / np.linalg.norm(p[1] - x[1]), 3.0, rtol=1e-10)


def test_pbd_with_one_pass_per_substep_is_the_lectures_loop(f64):
    """The lecture's pseudocode written out in numpy: per frame, numIter times, every particle's
    Verlet update under gravity (1.99 / 0.99), then every constraint relaxed in turn with the
    mass weights (1/m = 0 at the wall); visited in the model's colour order (any order is the
    lecture's "for each constraint"). ti_cloth's first step has no history and takes the
    second-order start x_1 = x_0 + h^2 g / 2 (verlet.py); the lecture's string has equal m."""
    num_iter, h, d, g = 3, 1 / 90, 0.01, np.array([0.0, -9.81, 0.0])
    body = tc.string(6, 0.5, mass=0.06, end_mass="full")
    sim = tc.Simulation(body, integrator=tc.PBD(iterations=1, damping=d), dt=h)
    order = sim.model.spring_colouring().order.to_numpy()[:body.spring_count]
    w = np.where(body.pinned, 0.0, 1.0 / body.particle_mass)
    x, prev = body.particle_position.copy(), None
    for frame in range(12):
        for _ in range(num_iter):
            moved = x + h * h * g / 2 if prev is None else x + (1 - d) * (x - prev) + h * h * g
            prev, x = x, np.where(body.pinned[:, None], x, moved)
            for s in order:
                p, q = body.spring_indices[s]
                delta = (np.linalg.norm(x[q] - x[p]) - body.spring_rest_length[s]) / np.linalg.norm(x[q] - x[p])
                dx = delta * (x[q] - x[p])
                x[p] += w[p] / (w[p] + w[q]) * dx
                x[q] -= w[q] / (w[p] + w[q]) * dx
        sim.step(num_iter)
        np.testing.assert_allclose(sim.positions(), x, atol=1e-12, err_msg=f"frame {frame}")
    assert x[-1, 1] < -0.05, "the string fell and swings"


def test_integrators_are_registered_by_name():
    """Each integrator is registered under its own name and states an order the
    zero-rest-length oscillator (test_extremes.py) holds it to."""
    for name, cls in tc.INTEGRATORS.items():
        assert cls.name == name and cls.order in (1, 2, 4)
