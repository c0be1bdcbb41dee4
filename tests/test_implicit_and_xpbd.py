"""implicit_euler (Baraff-Witkin, CG) and xpbd (compliance 1/k): against a dense solve of the
same linear system, the exact energy decay of backward Euler, and the Hookean statics."""


import warnings

import numpy as np
import pytest
from helpers import report, stretched_energy_ratios

import ti_cloth as tc
from ti_cloth.runtime import plan


def perturbed_cloth(damping):
    material = tc.Material(density=0.3, stretch=tc.SpringParams(400.0, 0.5),
                           shear=tc.SpringParams(40.0, 0.05), bend=tc.SpringParams(4.0, 0.01),
                           damping=damping)
    cloth = tc.Cloth(tc.grid_mesh(4, 5, size=(0.3, 0.4)), material, pinned=[0, 4])
    rng = np.random.default_rng(7)
    x = cloth.particle_position + rng.normal(scale=0.02, size=cloth.particle_position.shape)
    v = rng.normal(scale=0.3, size=x.shape)
    x[cloth.pinned] = cloth.particle_position[cloth.pinned]
    v[cloth.pinned] = 0.0
    return cloth, x, v


def dense_backward_euler_step(cloth, x, v, h, gravity, drag):
    """Assemble (M - h D - h^2 K) dv = h (f + h K v) with numpy and solve it on the free
    particles: the independent computation of one implicit_euler step."""
    n = cloth.particle_count
    m = cloth.particle_mass
    f = m[:, None] * (np.asarray(gravity) - drag * v)
    K = np.zeros((3 * n, 3 * n))
    D = np.zeros((3 * n, 3 * n))
    eye = np.eye(3)
    for (i, j), rest, k, kd in zip(cloth.spring_indices, cloth.spring_rest_length,
                                   cloth.spring_stiffness, cloth.spring_damping):
        d = x[i] - x[j]
        length = np.linalg.norm(d)
        u = d / length
        vij = v[i] - v[j]
        axial = cloth.damping == "axial"
        fs = -k * (length - rest) * u - (kd * vij.dot(u) * u if axial else kd * vij)
        f[i] += fs
        f[j] -= fs
        ks = k * (np.outer(u, u) + max(1 - rest / length, 0.0) * (eye - np.outer(u, u)))
        ds = kd * (np.outer(u, u) if axial else eye)
        for a, b, sign in ((i, i, -1), (j, j, -1), (i, j, 1), (j, i, 1)):
            K[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sign * ks
            D[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sign * ds
    D -= drag * np.diag(np.repeat(m, 3))
    A = np.diag(np.repeat(m, 3)) - h * D - h * h * K
    b = h * (f.ravel() + h * K @ v.ravel())
    free = np.repeat(~cloth.pinned, 3)
    dv = np.zeros(3 * n)
    dv[free] = np.linalg.solve(A[np.ix_(free, free)], b[free])
    v_new = v + dv.reshape(n, 3)
    return x + h * v_new, v_new


@pytest.mark.parametrize("damping", ["axial", "relative"])
def test_implicit_step_equals_dense_solve(f64, damping):
    cloth, x, v = perturbed_cloth(damping)
    h, gravity, drag = 1e-2, (0.0, -9.81, 0.0), 0.4
    integrator = tc.ImplicitEuler(tolerance=1e-13, max_iterations=500)
    sim = tc.Simulation(cloth, integrator=integrator, dt=h, gravity=gravity, drag=drag)
    sim.set_positions(x)
    sim.set_velocities(v)
    sim.step(1)
    x_ref, v_ref = dense_backward_euler_step(cloth, x, v, h, gravity, drag)
    err = np.abs(sim.velocities() - v_ref).max()
    report(f"{damping}: velocity difference to the dense solve [m/s] "
           f"({integrator.last_iterations} CG iterations)", err, "< 1e-10")
    assert err < 1e-10
    assert np.abs(sim.positions() - x_ref).max() < 1e-12
    assert integrator.last_iterations < 3 * cloth.particle_count, "CG converges within 3N iterations"


def test_implicit_cg_stops_at_its_tolerance(f64):
    """A looser tolerance stops earlier, with a residual within it."""
    cloth, x, v = perturbed_cloth("axial")
    first = {}
    for tol in (1e-3, 1e-9):
        integrator = tc.ImplicitEuler(tolerance=tol)
        sim = tc.Simulation(cloth, integrator=integrator, dt=1e-2)
        sim.set_positions(x)
        sim.set_velocities(v)
        sim.step(1)
        assert integrator.last_residual <= tol
        first[tol] = integrator.last_iterations
    report("CG iterations by tolerance", first, "fewer for 1e-3")
    assert first[1e-3] < first[1e-9]


def test_a_solve_that_runs_out_of_iterations_is_counted_and_warned_once(f64):
    """A step whose solve stops at its cap short of its tolerance is damped, not the implicit
    step asked for: each is counted (unconverged_solves) and the first warned of. Implicit
    Euler's count follows its own report, the residual each step leaves (one step at a time),
    and a batch of steps in one launch counts every one; a Newton integrator counts each of
    its solves (TR-BDF2: two a step); solves that converge count nothing."""
    cloth = tc.Cloth(tc.grid_mesh(10, 10, (0.5, 0.5)), tc.Material(), pinned=[0, 9])
    short = tc.ImplicitEuler(tolerance=1e-8, max_iterations=3)
    sim = tc.Simulation(cloth, integrator=short, dt=1 / 60)
    with pytest.warns(RuntimeWarning, match="max_iterations=3.*is damped") as caught:
        ran_out = 0
        for _ in range(5):
            sim.step(1)
            ran_out += short.last_residual > short.tolerance
            assert short.unconverged_solves == ran_out
        sim.step(4)
    assert ran_out == 5 and short.unconverged_solves == 9
    assert sum(issubclass(w.category, RuntimeWarning) for w in caught) == 1
    for make, per_step in ((tc.ImplicitMidpoint, 1), (tc.TRBDF2, 2)):
        newton = make(tolerance=1e-14, most_newton=2)
        # not "damped": an unconverged midpoint is doubled, and compression stalls Newton
        with pytest.warns(RuntimeWarning, match="most_newton=2.*doubles.*compressed"):
            tc.Simulation(cloth, integrator=newton, dt=1 / 60).step(3)
        assert newton.unconverged_solves == 3 * per_step
    for enough in (tc.ImplicitEuler(tolerance=1e-8, max_iterations=500), tc.ImplicitMidpoint()):
        sim = tc.Simulation(cloth, integrator=enough, dt=1 / 120)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            sim.step(5)
        assert enough.unconverged_solves == 0


@pytest.mark.parametrize("integrator", ["implicit_euler", "xpbd"])
def test_backward_euler_energy_decays_by_one_over_one_plus_h2w2(f64, integrator):
    """On a linear oscillator (a mass on a pinned spring moving along it) backward Euler
    multiplies the energy by exactly 1 / (1 + h^2 w^2) per step: the mirror image of
    explicit Euler's 1 + h^2 w^2. XPBD with compliance 1/k is the same map."""
    m, k, h = 0.5, 50.0, 0.01
    w2 = k / m
    cloth = tc.Cloth.from_particles([[0, 0, 0], [1, 0, 0]], [0.0, m], [[0, 1]],
                                    tc.Material(stretch=tc.SpringParams(k)), pinned=[0])
    spec = tc.ImplicitEuler(tolerance=1e-12) if integrator == "implicit_euler" else tc.XPBD(iterations=3)
    sim = tc.Simulation(cloth, integrator=spec, dt=h, gravity=(0, 0, 0))
    ratios = stretched_energy_ratios(sim)
    report(f"{integrator} E_(n+1)/E_n", (ratios.min(), ratios.max()), 1 / (1 + h * h * w2))
    np.testing.assert_allclose(ratios, 1 / (1 + h * h * w2), rtol=1e-9)


def hanging_string(k):
    return tc.string(9, 1.0, mass=0.05, stretch=tc.SpringParams(k, 0.2), direction=(0, -1, 0),
                     fixed="start")


def segment_lengths(sim):
    return np.linalg.norm(np.diff(sim.positions(), axis=0), axis=1)


@pytest.mark.parametrize("integrator", ["implicit_euler", "xpbd"])
def test_hanging_string_stretches_by_hooke(f64, integrator):
    """At rest, segment s carries the weight below it: length L + g m_below / k, the same
    Hookean statics as the force-based integrators, even at a step 10x beyond the explicit
    limit. Gauss-Seidel needs more passes as h^2 k / m grows: here XPBD is converged at 300
    (10 passes leave 1.7 cm, 100 leave 3e-5 m, measured)."""
    cloth = hanging_string(200.0)
    dt = 10 * tc.stable_dt(cloth, "symplectic_euler")
    spec = tc.XPBD(iterations=300) if integrator == "xpbd" else integrator
    sim = tc.Simulation(cloth, integrator=spec, dt=dt, gravity=(0, -9.81, 0))
    sim.step(int(round(20 / dt)))
    m = cloth.particle_mass
    below = np.cumsum(m[::-1])[::-1][1:]
    expected = cloth.spring_rest_length + 9.81 * below / cloth.spring_stiffness
    err = np.abs(segment_lengths(sim) - expected).max()
    report(f"{integrator} at dt = {dt:.3g} s: segment length error [m]", err, "< 1e-7")
    assert err < 1e-7


def test_xpbd_stiffness_is_the_material_not_the_iteration_count(f64):
    """XPBD's converged answer does not depend on iterations; PBD's apparent stiffness does."""
    cloth = hanging_string(50.0)
    stretch = {}
    for name, spec in (("xpbd", tc.XPBD), ("pbd", tc.PBD)):
        for iterations in (30, 120):
            sim = tc.Simulation(cloth, integrator=spec(iterations=iterations), dt=1 / 60)
            sim.step(600)
            stretch[name, iterations] = segment_lengths(sim).sum() - 1.0
    below = np.cumsum(cloth.particle_mass[::-1])[::-1][1:]
    hooke = float(np.sum(9.81 * below / cloth.spring_stiffness))
    report("total stretch [m] by (integrator, iterations)", stretch, f"xpbd: {hooke:.6g}")
    assert stretch["xpbd", 30] == pytest.approx(hooke, rel=1e-3)
    assert stretch["xpbd", 120] == pytest.approx(hooke, rel=1e-3)
    assert stretch["pbd", 30] > 2 * stretch["pbd", 120] > 0
    assert stretch["pbd", 30] < 0.5 * hooke


@pytest.mark.parametrize("option, value", [("tolerance", 0.0), ("tolerance", 1.0),
                                           ("max_iterations", 0), ("max_iterations", 2.5)])
def test_implicit_options_are_validated(option, value):
    with pytest.raises(ValueError, match=f"ImplicitEuler.{option} must be"):
        tc.ImplicitEuler(**{option: value})


def test_xpbd_iterations_validated():
    with pytest.raises(ValueError, match=r"XPBD.iterations must be an int in \[1, 10_000\], got 0"):
        tc.XPBD(iterations=0)


@pytest.mark.slow
@pytest.mark.parametrize("integrator, body", [(tc.PBD(iterations=4), "sheet"), (tc.XPBD(iterations=4), "sheet"),
                                             (tc.XPBD(iterations=4), "braced strand")],
                         ids=["pbd-sheet", "xpbd-sheet", "xpbd-braced strand"])
def test_serial_and_parallel_sweeps_give_the_same_bits(f64, integrator, body, monkeypatch):
    """A launch per stage of the integrator's phases and of strain limiting's sweeps, serial
    or parallel: both visit the springs (and the altitude springs of a braced strand) colour
    by colour, so they agree exactly."""
    cloth = (tc.Cloth(tc.grid_mesh(6, 7, plane="xz"), tc.Material(), pinned=[0, 5]) if body == "sheet"
             else tc.hair([[0.0, 0.0, 0.0]], 2, 0.2, directions=[[1.0, 0.0, 0.0]], mass=1e-3))
    results = []
    sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 120, strain_limit=tc.StrainLimit(max_strain=0.05))
    for limit in (10**9, -1):                # the plan is chosen at every launch
        monkeypatch.setattr(plan, "SERIAL_SPRING_LIMIT", limit)
        sim.restart()
        sim.step(20, plan="per stage")
        results.append(sim.positions())
    assert np.abs(results[0] - cloth.particle_position).max() > 1e-4, "the body moved"
    np.testing.assert_array_equal(results[0], results[1])


@pytest.mark.reinitialises
@pytest.mark.parametrize("make", [tc.RK4, tc.ImplicitEuler, tc.XPBD], ids=["rk4", "implicit_euler", "xpbd"])
def test_an_integrator_reused_across_simulations_and_runtimes(make):
    """Working buffers belong to a State: a dropped simulation's go back to the pool with it
    and serve the next simulation of its structure, and after init() a reused integrator
    gives exactly what a fresh one gives."""
    import gc
    cloth = tc.Cloth(tc.grid_mesh(4, 4, plane="xz"), tc.Material(), pinned=[0, 3])
    shared = make()
    tc.init(precision="f64")
    first = tc.Simulation(cloth, integrator=shared, dt=1e-3)
    first.step(3)
    state, buffers = first.state, shared.buffers(first.state, lambda: None)
    del first
    gc.collect()
    second = tc.Simulation(cloth, integrator=make(), dt=1e-3)
    assert second.state is state
    assert second.integrator.buffers(second.state, lambda: None) is buffers
    tc.init(precision="f32")
    reused = tc.Simulation(cloth, integrator=shared, dt=1e-3)
    fresh = tc.Simulation(cloth, integrator=make(), dt=1e-3)
    reused.step(10)
    fresh.step(10)
    np.testing.assert_array_equal(reused.positions(), fresh.positions())
    assert reused.state is not state and shared.buffers(reused.state, lambda: None) is not None


def test_xpbd_damps_relative_motion_on_a_relative_damped_body(f64):
    """Two free particles joined by a spring of k = 0 (no constraint) and kd = 0.3 kg/s,
    relative damping (Stuyck eq. 4.7), no gravity, moving apart sideways: each xpbd step is the
    backward Euler step of -kd (v_p - v_q), so the relative velocity shrinks by exactly
    1 / (1 + h kd (1/m_p + 1/m_q)) per step and the momentum stays. Axial damping (the
    constraint's own) would leave this sideways motion undamped."""
    h, kd, masses = 1e-2, 0.3, np.array([0.1, 0.3])
    material = tc.Material(stretch=tc.SpringParams(0.0, kd), damping="relative")
    body = tc.Cloth.from_particles([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]], masses, [[0, 1]], material)
    sim = tc.Simulation(body, integrator=tc.XPBD(iterations=3), dt=h, gravity=(0, 0, 0))
    v0 = np.array([[0.0, 0.3, 0.1], [0.0, -0.1, 0.0]])
    sim.set_velocities(v0)
    sim.step(10)
    shrink = (1 + h * kd * (1 / masses).sum()) ** -10
    v = sim.velocities()
    np.testing.assert_allclose(v[0] - v[1], shrink * (v0[0] - v0[1]), atol=1e-14)
    np.testing.assert_allclose(masses @ v, masses @ v0, atol=1e-15)
