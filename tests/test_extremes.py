"""Numerical stability at the extremes: each case runs sanely or fails with a clear message.
The README's "Extremes" table lists what every integrator does; these tests hold its claims."""

import math

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc

# and xpbd on BDF2's step (XPBD.scheme), and that step with tethers (XPBD.tethers)
ALL = list(tc.INTEGRATORS) + ["xpbd bdf2", "xpbd tethered"]


def made(name: str):
    """The integrator a name of ALL stands for."""
    return {"xpbd bdf2": lambda: tc.XPBD(scheme="bdf2"),
            "xpbd tethered": lambda: tc.XPBD(**tc.XPBD.presets["tethered"])}.get(
        name, lambda: name)()


def hanging_sheet(k=800.0, density=0.15, kd=0.0):
    material = tc.Material(density=density, stretch=tc.SpringParams(k, kd), shear=tc.SpringParams(k / 10, kd / 10),
                           bend=tc.SpringParams(k / 800, kd / 800))
    return tc.Cloth(tc.grid_mesh(8, 8, size=(0.5, 0.5), plane="xz"), material, pinned=[0, 7])


def test_stiff_springs_at_frame_step_with_implicit_euler(f64):
    """k = 1e7 N/m at dt = 1/30 s (the explicit limit is ~1e-5 s): finite and bounded. The
    linearised step stretches springs that turn (at rest they have no transverse stiffness), so
    the first steps store spring energy (measured: 14 J at step 1, the flat sheet falling
    h^2 g away from its pins); backward Euler then dissipates it: no later step exceeds the
    first steps' peak and by the end the total is below the start."""
    cloth = hanging_sheet(k=1e7)
    assert tc.stable_dt(cloth, "symplectic_euler") < 1e-4
    sim = tc.Simulation(cloth, integrator="implicit_euler", dt=1 / 30)
    e0 = sim.energy()["total"]
    totals = []
    for _ in range(60):
        sim.step(1)
        totals.append(sim.energy()["total"] - e0)
    x = sim.positions()
    report("k=1e7 dt=1/30: total energy - start [J] (peak in 5 steps, peak after, final)",
           (max(totals[:5]), max(totals[5:]), totals[-1]), "later peak <= first, final < 0")
    assert np.isfinite(x).all()
    assert max(totals[5:]) <= max(totals[:5])
    assert totals[-1] < 0
    stretch = np.linalg.norm(x[cloth.spring_indices[:, 0]] - x[cloth.spring_indices[:, 1]], axis=1)
    assert np.abs(stretch / cloth.spring_rest_length - 1).max() < 0.01, "stiff cloth barely stretches"


@pytest.mark.parametrize("integrator", ALL)
def test_microgram_particles(f64, integrator):
    """1e-6 kg particles: the stable step shrinks with sqrt(m / k), dt="auto" follows it and the
    cloth hangs sanely (explicit Euler: damping makes a stable step exist)."""
    area = 0.5 * 0.5
    density = 1e-6 * 64 / area      # ~1e-6 kg per particle
    cloth = hanging_sheet(k=1.0, density=density, kd=1e-4)
    assert cloth.particle_mass.max() < 3e-6
    sim = tc.Simulation(cloth, integrator=made(integrator), dt="auto")
    sim.step(min(2000, int(0.2 / sim.dt)))
    x = sim.positions()
    assert np.isfinite(x).all() and x[:, 1].max() <= 1e-9
    assert x[:, 1].min() > -2.0, "fell as a cloth, no particle flung away"


@pytest.mark.parametrize("integrator", ALL)
def test_zero_length_rest_spring_is_an_isotropic_oscillator(f64, integrator):
    """A spring of rest length 0 pulls with -k x in every direction: a mass on one, pinned at
    the origin, orbits / oscillates with period 2 pi sqrt(m / k) in any direction; started on
    the pin it stays there (no direction, no force, no NaN)."""
    m, k = 0.1, 40.0
    cloth = tc.Cloth.from_particles([[0, 0, 0], [0, 0, 0]], [0.0, m], [[0, 1]],
                                    tc.Material(stretch=tc.SpringParams(k)), pinned=[0])
    assert cloth.spring_rest_length[0] == 0
    period = 2 * math.pi * math.sqrt(m / k)
    dt = period / 400
    spec = (tc.PBD(iterations=1, stiffness={"stretch": 0.0}) if integrator == "pbd"
            else made(integrator))
    sim = tc.Simulation(cloth, integrator=spec, dt=dt, gravity=(0, 0, 0))
    sim.step(10)
    assert np.all(sim.positions() == 0), "started on the pin: stays there"
    if integrator == "pbd":
        return   # pbd's constraint is a rigid zero-length rod: with it off nothing moves either
    if integrator == "xpbd tethered":      # a tether of rest length 0 holds it at the pin
        sim.set_positions(np.array([[0, 0, 0], [0.03, -0.04, 0.02]]))
        sim.step(1)
        assert np.all(sim.positions() == 0)
        return
    start = np.array([[0, 0, 0], [0.03, -0.04, 0.02]])
    sim.set_positions(start)
    sim.step(400)
    error = np.linalg.norm(sim.positions()[1] - start[1]) / np.linalg.norm(start[1])
    order = made(integrator).order if integrator == "xpbd bdf2" else tc.INTEGRATORS[integrator].order
    tol = 8 * (2 * math.pi / 400) ** order   # one period's phase error of an order-p method, x8
    report(f"{integrator}: back after one period (relative)", error, f"< {tol:.2g}")
    assert error < max(tol, 1e-9)


@pytest.mark.parametrize("integrator", ALL)
def test_every_particle_pinned(f64, integrator):
    cloth = tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=list(range(16)))
    sim = tc.Simulation(cloth, integrator=made(integrator), dt=1 / 60)
    assert sim.stable_dt() == math.inf
    sim.step(20)
    np.testing.assert_array_equal(sim.positions(), cloth.particle_position)
    assert not sim.velocities().any()


@pytest.mark.parametrize("integrator", ALL)
def test_no_springs_is_free_fall(f64, integrator):
    cloth = tc.Cloth.from_particles([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [0.1, 0.2, 0.3], np.zeros((0, 2), int),
                                    pinned=[2])
    h, n = 0.01, 50
    sim = tc.Simulation(cloth, integrator=made(integrator), dt=h)
    assert sim.stable_dt() == math.inf
    sim.step(n)
    drop = -sim.positions()[:2, 1]
    low, high = 9.81 * h * h * n * (n - 1) / 2, 9.81 * h * h * n * (n + 1) / 2   # first-order bounds
    report(f"{integrator} drop [m]", drop, (low, high))
    assert np.all((drop >= low - 1e-12) & (drop <= high + 1e-12))
    assert sim.positions()[2, 1] == 1.0


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet"])
def test_ten_minutes_undamped_energy_stays_bounded(f64, integrator):
    """600 simulated seconds of an undamped string swinging under gravity. A symplectic map
    conserves a modified energy within O(h w) of the true one, so the energy oscillates but
    does not drift: its mean over the last minute equals that over the first to 1 % of the
    energy scale, and no sample leaves the start by more than h w_max of it. The step is a
    fifth of the stable one: at h w = 1 (half of it) the 6:1 resonance of these maps (h w =
    2 sin(pi/6)) pumps the chain's nonlinear coupling and the energy did drift (measured)."""
    cloth = tc.string(4, 1.0, mass=0.1, stretch=tc.SpringParams(10.0), direction=(1, 0, 0))
    dt = 0.2 * tc.stable_dt(cloth, integrator)
    w_max = 2 / tc.stable_dt(cloth, "symplectic_euler")
    sim = tc.Simulation(cloth, integrator=integrator, dt=dt)
    scale = 0.1 * 9.81 * 1.0
    e0 = sim.energy()["total"]
    per_second = int(round(1 / dt))
    energy = []
    for _ in range(600):
        sim.step(per_second)
        energy.append(sim.energy()["total"])
    energy = (np.array(energy) - e0) / scale
    drift = abs(energy[-60:].mean() - energy[:60].mean())
    report(f"{integrator}: 600 s, dt = {dt:.3g} s: max |E - E0| / scale, drift of the mean",
           (np.abs(energy).max(), drift), f"<= {dt * w_max:.3g}, < 0.01")
    assert np.abs(energy).max() <= dt * w_max
    assert drift < 0.01


@pytest.mark.reinitialises
def test_f32_adds_only_rounding_error():
    """The same run in f32 and f64 (the study scene's flap, 0.5 s, symplectic Euler at half the
    stable step): f32 rounding (eps 6e-8 per operation) accumulates like a random walk over
    the n steps, eps sqrt(n) of the cloth size; allow 10x that."""
    results = {}
    for precision in ("f64", "f32"):
        tc.init(precision=precision)
        scene = tc.load_scene("demos/study_cloth.toml")
        sim = scene.build()
        sim.step(int(round(0.5 / sim.dt)))
        results[precision] = sim.positions()
    size = 0.6 * math.sqrt(2)
    bound = 10 * np.finfo(np.float32).eps * math.sqrt(sim.step_count) * size
    added = np.abs(results["f32"] - results["f64"]).max()
    report(f"f32 - f64 after {sim.step_count} steps [m]", added, f"< {bound:.2g}")
    assert 0 < added < bound
